"""DPNV with a damping fitness averaged over several starts: does it make solutions more general?

    python -m experiments.dpnv_fitness_starts --starts 16 --seeds 20

Sigmoid NEAT, the signed coding, NEAT C++ 1.2.1's test of a generation (the species champion)
and the ``neat-1.2.1-dpnv-per-gene`` GA, on tuning seeds 5000 + i unless ``--first-seed``, with a budget of 100,000
evaluations. The fitness of a genome is its mean damping fitness from the standard start and
``starts - 1`` fixed random starts, drawn uniformly within Gruau's ranges (seed 0), not from the
625-start grid the generalisation test uses. Prints one JSON line: solved runs, evaluations as
NEAT 1.2.1 counts them (one evaluation is one genome, whatever its episodes), and the
generalisation (of 625) of each solving champion.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import torch

from evolution import NEAT, TaskFitness
from tasks.studies.double_pole import (
    SpeciesChampionTest,
    champions_test,
    study_config,
    study_spec,
    study_task,
)
from tasks.studies.double_pole_report import neat121_counts
from tasks.studies.generalization import GRUAU_RANGES

BUDGET = 100_000  # evaluations


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--starts", type=int, default=4, help="episodes per evaluation: the standard start and K-1 random")
    p.add_argument("--seeds", type=int, default=20, help="runs, on seeds FIRST, FIRST + 1, ...")
    p.add_argument("--first-seed", type=int, default=5000, help="the first seed (default 5000: tuning seeds)")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    seeds = list(range(a.first_seed, a.first_seed + a.seeds))
    task, spec = study_task("dpnv", "signed"), study_spec("dpnv", "sigmoid", "signed")
    cfg = study_config("dpnv", "sigmoid", ga="neat-1.2.1-dpnv-per-gene", coding="signed")
    random = torch.zeros(a.starts - 1, 6, dtype=torch.float64)
    unit = torch.rand(a.starts - 1, 4, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    random[:, :4] = (unit * 2 - 1) * torch.tensor(GRUAU_RANGES, dtype=torch.float64)
    starts = task.starts(torch.cat([task.reset(1)[:, :6].to(torch.float64), random]))
    neat = NEAT(cfg, seeds=seeds)
    general: dict[int, int] = {}

    def passes(champions):  # champions_pass, keeping the generalisation of those that pass
        ok, held = champions_test(champions, cfg, spec, task=task)
        for row, run in enumerate(torch.nonzero(neat.active_runs).flatten().tolist()):
            if ok[row]:
                general[run] = int(held[row])
        return ok

    start = time.process_time()
    neat.run(TaskFitness(task, cfg, spec, episodes=a.starts, starts=starts), BUDGET // cfg.pop_size,
             solved_fn=SpeciesChampionTest(neat, passes))
    evals = neat121_counts(cfg.pop_size, neat.solved_generation.tolist(), neat.solved_position.tolist())
    solved = [e for e in evals if e is not None]
    print(json.dumps({"starts": a.starts, "seeds": f"{seeds[0]}-{seeds[-1]}", "solved": f"{len(solved)}/{len(seeds)}",
                      "mean": round(statistics.mean(solved)) if solved else None,
                      "median": statistics.median(solved) if solved else None,
                      "generalization_mean": round(statistics.mean(general.values()), 1) if general else None,
                      "cpu_s": round(time.process_time() - start, 1), "evaluations": evals,
                      "generalization": [general.get(r) for r in range(len(seeds))]}))


if __name__ == "__main__":
    main()
