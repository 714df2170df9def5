"""What a study's runs leave behind, and what every report computes from it: ``ControllerRuns``
(one controller's runs), the controllers' labels, the U-test, the example run and PNG output.
"""

from __future__ import annotations

import csv
import io
import json
import os
import statistics
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from torch import Tensor

from evolution.config import NEATConfig
from evolution.population import Genomes

__all__ = ["LABELS", "ControllerRuns", "mann_whitney", "example_run", "example_label", "save_png", "ReportWriter"]

LABELS = {"snn": "NEAT-SNN", "sigmoid": "NEAT original (sigmoid)"}


@dataclass
class ControllerRuns:
    """Everything a table row, Fig. 8 and the champion plots need, for one controller."""

    controller: str
    seeds: list[int]
    generations: int
    solved_generation: list[int]  # 1-based; -1 = not solved within the budget
    best_fitness: list[float]  # champion's fitness (control steps) per run
    history: Tensor  # [generations, R]: best fitness so far after each generation
    champions: Genomes  # [R, 1]
    config: NEATConfig
    wall_s: float
    extra: dict = field(default_factory=dict)

    def champion_sizes(self) -> tuple[list[int], list[int]]:
        """Each run's champion: hidden nodes and enabled connections."""
        c = self.config
        hidden = self.champions.node[:, 0].sum(-1) - c.num_inputs - c.num_bias - c.num_outputs
        return hidden.tolist(), self.champions.enabled[:, 0].sum((-1, -2)).tolist()

    def counted(self) -> list[int]:
        """Solving generation per run, failures as ``generations + 1``."""
        return [g if g > 0 else self.generations + 1 for g in self.solved_generation]

    def row(self) -> dict:
        counted = self.counted()
        failures = sum(g <= 0 for g in self.solved_generation)
        return {"controller": self.controller, "best": min(counted), "worst": max(counted),
                "median": statistics.median(counted), "mean": statistics.mean(counted),
                "failures": failures, "runs": len(counted), "failure_rate": f"{failures}/{len(counted)}",
                "wall_s": self.wall_s, "ga": self.extra.get("ga", ""),
                **({"coding": self.extra["coding"]} if self.extra.get("coding", "study") != "study" else {})}


def mann_whitney(a: list[int], b: list[int]) -> dict:
    """Two-sided Mann-Whitney U test (scipy) of generations-to-solve, failures as 101."""
    from scipy.stats import mannwhitneyu

    if len(set(a) | set(b)) == 1:
        return {"U": float("nan"), "p_value": 1.0, "note": "all values equal"}
    res = mannwhitneyu(a, b, alternative="two-sided")
    return {"U": float(res.statistic), "p_value": float(res.pvalue)}


def example_run(r: ControllerRuns) -> int:
    """The first solved run (the paper plots a solved controller), else the fittest."""
    solved = [i for i, g in enumerate(r.solved_generation) if g > 0]
    return solved[0] if solved else max(range(len(r.best_fitness)), key=r.best_fitness.__getitem__)


def save_png(fig, path: Path) -> Path:
    """``fig`` as PNG (150 dpi), written atomically with the umask's mode."""
    import io

    from evolution.checkpoint import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=150)
    return atomic_write_bytes(path, buf.getvalue())



def example_label(r: ControllerRuns, run: int) -> str:
    """``"NEAT-SNN, seed 3, solved at generation 5"``: a run as the report's plots name it."""
    solved = r.solved_generation[run]
    return f"{LABELS.get(r.controller, r.controller)}, seed {r.seeds[run]}" + (
        f", solved at generation {solved}" if solved > 0 else ", not solved")


class ReportWriter:
    """The skeleton every study's report shares. ``summary.json`` and then ``NAME.md`` are written
    last (``finish``) and removed first (here): a report interrupted part way has no ``NAME.md``,
    so one that has it is complete. Every file is written atomically; ``written`` lists them."""

    def __init__(self, out: str | os.PathLike, name: str) -> None:
        self.out, self.name = Path(out), name
        for last in (self.out / f"{name}.md", self.out / "summary.json"):
            last.unlink(missing_ok=True)
        self.written: list[Path] = []

    def text(self, filename: str, text: str) -> Path:
        from evolution.checkpoint import atomic_write_bytes

        self.written.append(atomic_write_bytes(self.out / filename, text.encode()))
        return self.written[-1]

    def rows(self, filename: str, header: list[str], rows: Iterable[list]) -> Path:
        """A CSV file of ``header`` and ``rows``."""
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(header)
        w.writerows(rows)
        return self.text(filename, buf.getvalue())

    def png(self, fig, filename: str) -> Path:
        self.written.append(save_png(fig, self.out / filename))
        return self.written[-1]

    def champions(self, results: dict[str, ControllerRuns]) -> None:
        """Every run's champion genome, ``champions/CONTROLLER_seedSEED.json``."""
        from evolution.genome_io import save_genome

        for c, r in results.items():
            for i, seed in enumerate(r.seeds):
                self.written.append(save_genome(self.out / "champions" / f"{c}_seed{seed}.json",
                                                r.champions.select_runs([i]), r.config, fitness=r.best_fitness[i]))

    def finish(self, summary: dict, markdown: str) -> list[Path]:
        """``summary.json``, then ``NAME.md``: the report is complete. Returns every path written."""
        self.text("summary.json", json.dumps(summary, indent=2, default=float))
        self.text(f"{self.name}.md", markdown)
        return self.written
