"""First look at evolving double-pole controllers on tuning seeds (5000 + i), before the 60-seed study.

    python -m experiments.double_pole_tune --kind sigmoid --seeds 10 --gens 40
    python -m experiments.double_pole_tune --kind sigmoid --seeds 10 --gens 40 --bounds "[2.4,2,0.3,2,0.3,4]"

Prints each run's best fitness (control steps on DPV, Gruau's fitness on DPNV) every generation.
``--bounds`` replaces the task's observation bounds (the seam normalises over them), ``--cfg``
and ``--spec`` take JSON overrides of the NEAT config and the controller spec.
A run is solved by NEAT 2002's test (``champion_solves`` on the same task): on DPV its champion
balances 100,000 steps, on DPNV also 200 of the 625 generalisation starts; solved runs freeze.
"""

from __future__ import annotations

import argparse
import json
import time

import torch

from evolution import NEAT, TaskFitness
from evolution.config import NEATConfig
from evolution.phenotype import SPIKING_SIGMA, SigmoidSpec, SpikingSpec
from tasks.double_pole import DoublePoleTask, champion_solves
from tasks.experiments.cartpole import ga_overrides


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--kind", default="sigmoid", choices=("sigmoid", "snn"))
    p.add_argument("--task", default="dpv", choices=("dpv", "dpnv"))
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--gens", type=int, default=30)
    p.add_argument("--pop", type=int, default=150)
    p.add_argument("--ga", default="neat-c++")
    p.add_argument("--cfg", default="{}")
    p.add_argument("--spec", default="{}")
    p.add_argument("--bounds", default=None, help="JSON list of symmetric observation bounds")
    a = p.parse_args()
    torch.set_num_threads(1)
    velocities = a.task == "dpv"
    bounds = None if a.bounds is None else tuple(json.loads(a.bounds))
    task = (DoublePoleTask.with_velocities if velocities else DoublePoleTask.without_velocities)(
        observation_bounds=bounds)
    base = dict(num_inputs=task.observation_size, num_outputs=1, pop_size=a.pop, max_hidden=16)
    if a.kind == "snn":
        base.update(num_bias=0, **SPIKING_SIGMA)
    else:
        base.update(num_bias=1, sigma_mutate_rate=0.0, compatibility_sigma_coefficient=0.0)
    base.update(ga_overrides(a.ga))
    base.update(json.loads(a.cfg))
    cfg = NEATConfig(**base)
    spec = (SpikingSpec if a.kind == "snn" else SigmoidSpec)(**json.loads(a.spec))
    fitness = TaskFitness(task, cfg, a.kind, spec)
    neat = NEAT(cfg, seeds=list(range(5000, 5000 + a.seeds)))
    t0 = time.time()
    for gen in range(a.gens):
        if not bool(neat.active_runs.any()):
            break
        genomes = neat.ask()
        f = neat.evaluate_active(fitness, genomes)
        neat.tell(f, champion_solves(genomes, f, cfg, a.kind, spec, velocities=velocities,
                                     min_general=0 if velocities else 200, task=task))
        best = [round(float(b), 3) for b in f.max(1).values]
        print(gen + 1, f"{time.time() - t0:.0f}s", "active", int(neat.active_runs.sum()), "best", best, flush=True)


if __name__ == "__main__":
    main()
