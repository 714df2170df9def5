"""DPNV with a damping fitness averaged over several starts: does it make solutions more general?

    python -m experiments.dpnv_fitness_starts --starts 16 --seeds 20

Sigmoid NEAT (``--kind snn``: NEAT-SNN), the signed coding (``--coding push-pull``: NEAT-SNN's DPNV coding), NEAT C++ 1.2.1's test of a generation (the species champion)
and the ``neat-1.2.1-dpnv-per-gene`` GA (``--ga``), on tuning seeds 5000 + i unless ``--first-seed``, with a budget of 100,000
evaluations. The fitness of a genome is its mean damping fitness from the standard start and
``starts - 1`` fixed random starts, drawn uniformly within Gruau's ranges (seed 0), not from the
625-start grid the generalisation test uses. Prints one JSON line: solved runs, evaluations as
NEAT 1.2.1 counts them (one evaluation is one genome, whatever its episodes), and the
generalisation (of 625) of each solving champion. ``--fitness damping-both-poles`` adds the short
pole's angle and angular velocity to the damping term. ``--network-ms`` sets the network time of a
control step for NEAT-SNN (substeps of 0.5 ms; the plant still moves 20 ms), ``--spec`` and
``--cfg`` take JSON overrides of the spec and the NEAT config (the spec's ``neuron`` by preset name,
``snn_torch.functional.izhikevich.PRESETS``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import replace

import torch

from evolution import NEAT, TaskFitness
from evolution.reporters import StdOutReporter
from snn_torch.functional.izhikevich import PRESETS
from tasks.studies.double_pole import (
    DPNV_EPISODE_STEPS,
    LONG_BALANCE_STEPS,
    SpeciesChampionTest,
    champions_test,
    damping_fitness_starts,
    study_config,
    study_spec,
    study_task,
)
from tasks.studies.double_pole_report import neat121_counts
from tasks.studies.generalization import (
    GENERALIZATION_STEPS,
    balanced_steps,
    generalization_starts,
)

BUDGET = 100_000  # evaluations


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--starts", type=int, default=4, help="episodes per evaluation: the standard start and K-1 random")
    p.add_argument("--seeds", type=int, default=20, help="runs, on seeds FIRST, FIRST + 1, ...")
    p.add_argument("--first-seed", type=int, default=5000, help="the first seed (default 5000: tuning seeds)")
    p.add_argument("--kind", default="sigmoid", choices=("sigmoid", "snn"), help="the controller")
    p.add_argument("--generations", type=int, default=None, help="default: 100,000 evaluations' worth")
    p.add_argument("--network-ms", type=float, default=None,
                   help="NEAT-SNN: network time per control step (ms; default the plant's 20 ms)")
    p.add_argument("--coding", default="signed", choices=("signed", "push-pull"),
                   help="the study's input coding (tasks.studies.double_pole.CODINGS)")
    p.add_argument("--fitness", default="damping", choices=("damping", "damping-both-poles"),
                   help="Gruau's damping fitness, or with the short pole in its damping term (tasks.double_pole)")
    p.add_argument("--spec", default="{}", help="JSON overrides of the controller spec")
    p.add_argument("--cfg", default="{}", help="JSON overrides of the NEAT config")
    p.add_argument("--ga", default="neat-1.2.1-dpnv-per-gene", help="GA preset, or 'tuned' (the study's pick)")
    p.add_argument("--progress", type=int, default=0, help="print a line every N generations (0: none)")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    task = study_task("dpnv", a.coding).with_fitness(a.fitness, DPNV_EPISODE_STEPS)
    if a.network_ms is not None:
        task.control_period_s = a.network_ms / 1000.0
    spec_overrides = json.loads(a.spec)
    if isinstance(spec_overrides.get("neuron"), str):  # a preset's name, e.g. "regular_spiking"
        spec_overrides["neuron"] = PRESETS[spec_overrides["neuron"]]
    elif isinstance(spec_overrides.get("neuron"), dict):  # a, b, c, d (and v_peak) over the study's neuron
        spec_overrides["neuron"] = study_spec("dpnv", a.kind, a.coding).neuron._replace(**spec_overrides["neuron"])
    spec = replace(study_spec("dpnv", a.kind, a.coding), **spec_overrides)
    cfg = study_config("dpnv", a.kind, ga=a.ga, coding=a.coding, **json.loads(a.cfg))
    starts = damping_fitness_starts(task, a.starts)
    neat = NEAT(cfg, seeds=seeds)
    if a.progress:
        neat.add_reporter(StdOutReporter(a.progress))
    general: dict[int, int] = {}

    def passes(champions):  # champions_pass, keeping the generalisation of those that pass
        ok, held = champions_test(champions, cfg, spec, task=task)
        for row, run in enumerate(torch.nonzero(neat.active_runs).flatten().tolist()):
            if ok[row]:
                general[run] = int(held[row])
        return ok

    start = time.process_time()
    generations = BUDGET // cfg.pop_size if a.generations is None else a.generations
    result = neat.run(TaskFitness(task, cfg, spec, episodes=a.starts, starts=starts), generations,
                      solved_fn=SpeciesChampionTest(neat, passes))
    # how far the unsolved runs got: their best genome's balance from the standard start (steps, up to
    # 100,000) and the generalisation starts it holds
    long = balanced_steps(result.best_genomes, cfg, spec, max_steps=LONG_BALANCE_STEPS, task=task)[:, 0, 0]
    held = (balanced_steps(result.best_genomes, cfg, spec, starts=generalization_starts(), task=task)
            >= GENERALIZATION_STEPS).sum(-1)[:, 0]
    evals = neat121_counts(cfg.pop_size, neat.solved_generation.tolist(), neat.solved_position.tolist())
    solved = [e for e in evals if e is not None]
    print(json.dumps({"kind": a.kind, "fitness": a.fitness, "ga": a.ga, "coding": a.coding, "network_ms": a.network_ms, "spec": a.spec, "cfg": a.cfg,
                      "generations": generations, "starts": a.starts, "seeds": f"{seeds[0]}-{seeds[-1]}", "solved": f"{len(solved)}/{len(seeds)}",
                      "mean": round(statistics.mean(solved)) if solved else None,
                      "median": statistics.median(solved) if solved else None,
                      "generalization_mean": round(statistics.mean(general.values()), 1) if general else None,
                      "cpu_s": round(time.process_time() - start, 1), "evaluations": evals,
                      "generalization": [general.get(r) for r in range(len(seeds))],
                      "best_long_steps": long.tolist(), "best_held": held.tolist()}))


if __name__ == "__main__":
    main()
