"""Pick each controller's GA settings on tuning seeds, the same way for every controller.

    python -m experiments.tune_ga table1 --controllers sigmoid --seeds 5000-5059

For every GA preset of ``TUNING_GRID`` (NEAT C++'s and neat-python's defaults) and every
survival threshold in ``--survival`` (the share of a species that breeds, the setting the
result turned out to depend on most), evolves ``--seeds`` runs of a controller on the
table's task and prints generations to solve (failures as ``--generations`` + 1). The pick is
the lowest mean, ties broken by the lower median, then by the order of the grid. Tuning
seeds (5000 and up) are never among the reported seed sets (0-59, 60-119), so a setting is
never chosen on the runs it is judged by. The picks used by ``snn-neat reproduce`` are
recorded in each study's ``tuned_ga`` (``tasks/studies/registry.py``), the numbers that chose them in
docs/reproducing.md.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import torch

from experiments.sensitivity import parse_value, seed_range, sweep

__all__ = ["tune", "TUNING_GRID"]

# The presets the tuning protocol compares (docs/reproducing.md): NEAT C++'s and neat-python's
# defaults. NEAT C++ 1.2.1's double-pole files (also in GA_PRESETS) came later, as presets of their own.
TUNING_GRID = ("neat-c++", "neat-python")


def tune(table: str, controller: str, seeds: list[int], *, survival: list[float], generations: int = 100,
         presets: tuple[str, ...] = TUNING_GRID,
         report: Callable[[dict], None] | None = None) -> tuple[list[dict], dict]:
    """Rows (one per preset and threshold, each passed to ``report`` as it is done) and the row picked."""
    rows = []
    for ga in presets:
        for value in survival:
            row = sweep(table, "survival_threshold", [value], seeds, generations=generations,
                        controllers=(controller,), ga=ga)[0]
            rows.append({**row, "ga": ga})
            if report is not None:
                report(rows[-1])
    best = min(rows, key=lambda r: (r["mean"], r["median"]))
    return rows, best


def _line(r: dict) -> str:
    return (f"{r['ga']:>12} {r['value']:>9g} {r['median']:>7g} {r['mean']:>7.2f} "
            f"{r['failures']:>5}/{r['runs']:<3} {r['wall_s']:>7.0f}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("table", choices=["table1", "table2"])
    ap.add_argument("--controllers", default="snn,sigmoid")
    ap.add_argument("--seeds", type=seed_range, default=seed_range("5000-5059"), help="default 5000-5059")
    ap.add_argument("--survival", default="0.1,0.2", help="survival thresholds to try (default 0.1,0.2)")
    ap.add_argument("--generations", type=int, default=100)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    survival = [parse_value(v, "survival_threshold") for v in args.survival.split(",")]
    for controller in (c.strip() for c in args.controllers.split(",")):
        print(f"{args.table} {controller}, seeds {args.seeds[0]}-{args.seeds[-1]}")
        print(f"{'GA preset':>12} {'survival':>9} {'median':>7} {'mean':>7} {'failures':>9} {'wall s':>7}", flush=True)
        _, best = tune(args.table, controller, args.seeds, survival=survival, generations=args.generations,
                       report=lambda r: print(_line(r), flush=True))
        print(f"picked: {_line(best).strip()}", flush=True)


if __name__ == "__main__":
    main()
