"""NEAT C++ 1.2.1's own double-pole runs, measured on this project's machine, run by run, and the
tests that compare a study's runs with them.

``neat121_runs.json`` (next to this module) holds, per variant, each run's seed, evaluations to
solve as NEAT 1.2.1 counts them (``pop_size * (generation - 1) + the winner's position``; null for a
run that did not solve in its 100 generations), the generalisation of its solution (DPNV: starts
of 625) and its CPU seconds. How they were measured is in the file's ``source``. The issue's
fidelity test is a Mann-Whitney U test against this distribution, not against its mean.
"""

from __future__ import annotations

import json
import statistics
from dataclasses import dataclass
from functools import cache
from pathlib import Path

__all__ = ["DATA_FILE", "Neat121Runs", "neat121_runs", "compare_with_neat121"]

DATA_FILE = Path(__file__).with_name("neat121_runs.json")


@dataclass(frozen=True)
class Neat121Runs:
    """One variant's runs of NEAT C++ 1.2.1 (lists in seed order; None: the run did not solve)."""

    variant: str
    parameter_file: str
    population: int
    seeds: list[int]
    evaluations: list[int | None]
    generalization: list[int | None]
    cpu_s: list[float]
    source: str

    @property
    def solved_evaluations(self) -> list[int]:
        return [e for e in self.evaluations if e is not None]

    @property
    def failures(self) -> int:
        return sum(e is None for e in self.evaluations)

    def row(self) -> dict:
        """The report's row (``tasks.studies.double_pole.PUBLISHED`` form)."""
        solved = self.solved_evaluations
        gen = [g for g in self.generalization if g is not None]
        row = {"method": "NEAT C++ 1.2.1", "neat121_mean": round(statistics.mean(solved)),
               "neat121_median": statistics.median(solved), "failures": f"{self.failures}/{len(self.evaluations)}",
               "population": self.population,
               "source": f"measured here, seeds {self.seeds[0]}-{self.seeds[-1]} (tasks/studies/neat121_runs.json)"}
        if gen:
            row["generalization"] = round(statistics.mean(gen), 1)
        return row


@cache
def neat121_runs(variant: str) -> Neat121Runs:
    """NEAT C++ 1.2.1's runs of ``variant`` ("dpv" or "dpnv"); ``ValueError`` naming the file and
    the field if the data file is malformed."""
    data = json.loads(DATA_FILE.read_text())
    if variant not in data:
        raise ValueError(f"{DATA_FILE.name} has no runs of {variant!r} (it has {sorted(k for k in data if k != 'source')})")
    runs = data[variant]
    n = len(runs.get("seeds", []))
    for key in ("evaluations", "generalization", "cpu_s"):
        if not isinstance(runs.get(key), list) or len(runs[key]) != n:
            raise ValueError(f"{DATA_FILE.name}: {variant}.{key} must list one value per seed ({n})")
    return Neat121Runs(variant, runs["parameter_file"], int(runs["population"]), list(runs["seeds"]),
                       list(runs["evaluations"]), list(runs["generalization"]), list(runs["cpu_s"]), data["source"])


def compare_with_neat121(evaluations: list[int | None], variant: str) -> dict:
    """A study's runs against NEAT C++ 1.2.1's: ``evaluations`` per run as NEAT 1.2.1 counts them
    (None: not solved). Mann-Whitney U (two-sided) over the solved runs' evaluations, Fisher's
    exact test (two-sided) over the failures; medians and failure counts beside them."""
    from scipy.stats import fisher_exact, mannwhitneyu

    theirs = neat121_runs(variant)
    ours = [e for e in evaluations if e is not None]
    out = {"runs": len(evaluations), "failures": len(evaluations) - len(ours),
           "neat121_runs": len(theirs.evaluations), "neat121_failures": theirs.failures,
           "median": statistics.median(ours) if ours else None,
           "neat121_median": statistics.median(theirs.solved_evaluations)}
    if ours:
        mw = mannwhitneyu(ours, theirs.solved_evaluations, alternative="two-sided")
        out.update(U=float(mw.statistic), mann_whitney_p=float(mw.pvalue))
    table = [[out["failures"], len(ours)], [theirs.failures, len(theirs.solved_evaluations)]]
    out["fisher_p"] = float(fisher_exact(table).pvalue)
    return out
