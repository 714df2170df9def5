"""``snn-neat evolve``: one controller, one seed, on one of the paper's cart-pole tasks; resumable.

The run is checkpointed to ``OUT/evolve.ckpt`` after every ``checkpoint_every`` generations
(``tasks.studies.resumable``), with the statistics rows so far, so a killed run continues
with ``resume=True`` to the same statistics and champion as an uninterrupted one.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from evolution.config import NEATConfig
from evolution.neat import NEAT, NEATResult
from evolution.reporters import StatisticsReporter, StdOutReporter, TqdmReporter
from tasks.studies.resumable import RunCheckpoint, open_run

__all__ = ["EvolveResult", "run_evolve", "write_evolve_report"]

CHECKPOINT = "evolve.ckpt"


@dataclass
class EvolveResult:
    result: NEATResult
    statistics: StatisticsReporter
    config: NEATConfig


def run_evolve(controller: str, task: str, seed: int, generations: int, out: str | os.PathLike, *,
               resume: bool = False, self_loops: bool = False, ga: str = "tuned", device: str = "cpu",
               verbose: bool = False, report_every: int = 1, checkpoint_every: int = 1,
               stop_after: int | None = None, progress: bool = True) -> EvolveResult:
    """Evolve ``controller`` (snn or sigmoid) on ``task`` (nonmarkov: Table II; markov: Table I)
    for up to ``generations`` generations, with a line per generation (``verbose``), else a
    progress bar unless ``progress`` is False. ``stop_after`` (generations in this call) exists
    for tests of interruption."""
    from tasks.studies.registry import describe_ga, study

    s = study("table1" if task == "markov" else "table2")
    preset, extra = s.ga_choice(controller, ga)
    identity = {"command": "evolve", "task": task, "controller": controller, "seed": seed, "generations": generations,
                "self_loops": self_loops, "ga": describe_ga(preset, extra)}
    path = Path(out) / CHECKPOINT
    neat, data = open_run(path, identity, resume=resume, device=device, fresh=lambda: NEAT(
        s.config(controller, self_loops=self_loops, ga=ga), seeds=[seed], device=device))
    config = neat.config
    stats = neat.add_reporter(StatisticsReporter())
    stats.rows = [dict(row) for row in data.get("statistics", [])]
    shown = None
    if verbose:
        shown = neat.add_reporter(StdOutReporter(every=report_every))
    elif progress:
        shown = neat.add_reporter(TqdmReporter(total=generations, initial=neat.generation))
    neat.add_reporter(RunCheckpoint(path, identity, generations, every=checkpoint_every,
                                    records=lambda: {"statistics": stats.rows}, wall_s=float(data.get("wall_s", 0.0))))
    budget = generations - neat.generation
    try:
        result = neat.run(s.fitness(controller, config),
                          budget if stop_after is None else min(budget, stop_after))
    finally:
        if isinstance(shown, TqdmReporter):
            shown.end_run(None)  # closed now: a bar closed at exit would draw over an interruption's message
    return EvolveResult(result, stats, config)


def write_evolve_report(r: EvolveResult, out: str | os.PathLike) -> list[Path]:
    """``statistics.csv``, then ``champion.json`` (removed first, written last: its presence
    marks a complete report)."""
    from evolution.genome_io import save_genome

    out = Path(out)
    (out / "champion.json").unlink(missing_ok=True)
    return [r.statistics.save_csv(out / "statistics.csv"),
            save_genome(out / "champion.json", r.result.best_genomes, r.config,
                        fitness=r.result.best_fitness[0].item())]
