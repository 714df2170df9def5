"""First look at evolving double-pole controllers on tuning seeds (5000 + i), before the 60-seed study.

    python -m experiments.double_pole_tune --kind snn --seeds 10 --gens 40
    python -m experiments.double_pole_tune --kind sigmoid --seeds 10 --gens 40 --ga neat-c++ --bounds "[2.4,1,0.26,1,0.26,1]"

Prints each run's best fitness (control steps on DPV, Gruau's fitness on DPNV) every generation.
Defaults: the study's settings (``tasks.studies.double_pole``). ``--bounds`` replaces the
task's observation bounds (the seam normalises over them), ``--cfg``
and ``--spec`` take JSON overrides of the NEAT config and the controller spec.
A run is solved by NEAT 2002's test (``champion_solves`` on the same task): on DPV its champion
balances 100,000 steps, on DPNV also 200 of the 625 generalisation starts; solved runs freeze.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace

import torch

from evolution import NEAT, TaskFitness
from tasks.double_pole import DoublePoleTask
from tasks.studies.double_pole import (
    SpeciesChampionTest,
    champion_solves,
    champions_pass,
    study_config,
    study_spec,
    study_task,
)
from tasks.studies.generalization import generalization_starts


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--kind", default="sigmoid", choices=("sigmoid", "snn"))
    p.add_argument("--task", default="dpv", choices=("dpv", "dpnv"))
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--gens", type=int, default=30)
    p.add_argument("--pop", type=int, default=None, help="population (default: the study's, 150 DPV / 1000 DPNV)")
    p.add_argument("--ga", default="tuned", help="GA preset, or 'tuned': the study's pick (STUDIES[...].tuned_ga)")
    p.add_argument("--cfg", default="{}")
    p.add_argument("--spec", default="{}")
    p.add_argument("--bounds", default=None, help="JSON list of symmetric observation bounds")
    p.add_argument("--coding", default="study", choices=("study", "signed"), help="the study's input coding")
    p.add_argument("--episode-steps", type=int, default=None, help="DPNV: the damping fitness's episode (default 1000)")
    p.add_argument("--starts", type=int, default=1,
                   help="DPNV: the fitness's episodes: the standard start, then starts drawn from Gruau's 625 "
                        "(the mean damping fitness over them)")
    p.add_argument("--test", default="champion", choices=("champion", "species"),
                   help="DPNV's test of a generation: the overall champion (NEAT 2002 as read here) or NEAT C++ "
                        "1.2.1's champion of the best species not tested since its last record")
    a = p.parse_args()
    torch.set_num_threads(1)
    velocities = a.task == "dpv"
    task = study_task(a.task, a.coding)
    if a.bounds is not None or a.episode_steps is not None:
        task = DoublePoleTask(velocities=velocities, fitness="steps" if velocities else "damping",
                              max_steps=a.episode_steps or task.max_steps,
                              observation_bounds=tuple(json.loads(a.bounds)) if a.bounds else task.observation_high)
    cfg = study_config(a.task, a.kind, ga=a.ga, coding=a.coding, **({} if a.pop is None else {"pop_size": a.pop}),
                       **json.loads(a.cfg))
    spec = replace(study_spec(a.task, a.kind, a.coding), **json.loads(a.spec))
    starts = None
    if a.starts > 1:  # the standard start and Gruau's starts drawn from the grid (seed 0)
        grid = generalization_starts()
        grid = grid[grid.abs().sum(1) > 0]  # not the rest state: its damping term 0.75 / J divides by J = 0
        chosen = grid[torch.randperm(len(grid), generator=torch.Generator().manual_seed(0))[: a.starts - 1]]
        standard = task.reset(1)[:, :6]
        starts = task.starts(torch.cat([standard, chosen]))
    fitness = TaskFitness(task, cfg, spec, episodes=a.starts, starts=starts)
    neat = NEAT(cfg, seeds=list(range(5000, 5000 + a.seeds)))
    species_test = SpeciesChampionTest(neat, lambda champions: champions_pass(champions, cfg, spec, task=task))
    t0 = time.time()
    for gen in range(a.gens):
        if not bool(neat.active_runs.any()):
            break
        genomes = neat.ask()
        f = neat.evaluate_active(fitness, genomes)
        test = species_test if a.test == "species" else (
            lambda g, fit: champion_solves(g, fit, cfg, spec, task=task))
        solved = None if velocities else neat.solved_active(test, genomes, f)  # DPV: the config's threshold
        neat.tell(f, solved)
        best = [round(float(b), 3) for b in f.max(1).values]
        print(gen + 1, f"{time.time() - t0:.0f}s", "active", int(neat.active_runs.sum()), "best", best, flush=True)


if __name__ == "__main__":
    main()
