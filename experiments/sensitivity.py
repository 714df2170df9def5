"""How much does one NEAT setting move a reproduction's result?

    python -m experiments.sensitivity table2 --param weight_mutate_power --values 0.5,1,2.5 --seeds 0-59

For each value of ``--param`` (any ``NEATConfig`` field), evolves ``--seeds`` runs of each
controller on the table's task, all runs of a controller in one batch, with everything else
as ``snn-neat reproduce`` has it, and prints generations to solve (failures counted as
``--generations`` + 1), failures and the Mann-Whitney U p-value of NEAT-SNN against sigmoid
NEAT. No checkpoints: for a table with resume and plots, use ``snn-neat reproduce``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution.neat import NEAT
from tasks.studies.registry import study
from tasks.studies.results import mann_whitney

__all__ = ["sweep", "seed_range", "parse_value"]


def sweep(table: str, param: str, values: list[float], seeds: list[int], *, generations: int = 100,
          controllers: tuple[str, ...] = ("snn", "sigmoid"), ga: str = "neat-c++") -> list[dict]:
    """One row per (value, controller): median, mean, failures and wall time."""
    task = study(table)
    rows = []
    for value in values:
        counted = {}
        for c in controllers:
            config = task.config(c, ga=ga, **{param: value})
            start = time.perf_counter()
            result = NEAT(config, seeds=seeds).run(task.fitness(c, config), generations)
            gens = [g if g > 0 else generations + 1 for g in result.solved_generation.tolist()]
            counted[c] = gens
            rows.append({"value": value, "controller": c, "median": statistics.median(gens),
                         "mean": statistics.mean(gens), "failures": sum(g > generations for g in gens),
                         "runs": len(gens), "wall_s": time.perf_counter() - start})
        if len(controllers) == 2:
            rows[-1]["p_value"] = mann_whitney(counted[controllers[0]], counted[controllers[1]])["p_value"]
    return rows


def parse_value(text: str, param: str) -> bool | int | float:
    """A swept value of ``NEATConfig.<param>``, of that field's type (bool, int or float)."""
    from dataclasses import fields

    from evolution.config import ConfigError, NEATConfig

    spec = {f.name: f for f in fields(NEATConfig)}.get(param)
    if spec is None:
        raise ConfigError(f"--param {param!r} is not a NEATConfig field")
    text = text.strip()
    try:
        if spec.type in ("bool", bool):
            if text.lower() not in ("true", "false"):
                raise ValueError(text)
            return text.lower() == "true"
        return int(text) if spec.metadata.get("integer") else float(text)
    except ValueError:
        raise ConfigError(f"--values: {text!r} is not a valid value of NEATConfig.{param}") from None


def seed_range(text: str) -> list[int]:
    """``"0-59"`` -> [0, ..., 59]; ``"7"`` -> [7]."""
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("table", choices=["table1", "table2"])
    ap.add_argument("--param", required=True, help="a NEATConfig field, e.g. weight_mutate_power")
    ap.add_argument("--values", required=True, help="comma-separated values")
    ap.add_argument("--seeds", type=seed_range, default=seed_range("0-59"), help="e.g. 0-59 (default)")
    ap.add_argument("--generations", type=int, default=100)
    ap.add_argument("--controllers", default="snn,sigmoid")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--ga", default="neat-c++", help="GA preset the swept field overrides (neat-c++ or neat-python)")
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    values = [parse_value(v, args.param) for v in args.values.split(",")]
    controllers = tuple(c.strip() for c in args.controllers.split(","))
    print(f"{args.table}, GA {args.ga}, {args.param} in {values}, seeds {args.seeds[0]}-{args.seeds[-1]}")
    print(f"{'value':>8} {'controller':>10} {'median':>7} {'mean':>7} {'failures':>9} {'wall s':>7} {'U-test p':>9}")
    for row in sweep(args.table, args.param, values, args.seeds, generations=args.generations,
                     controllers=controllers, ga=args.ga):
        p = f"{row['p_value']:.2g}" if "p_value" in row else ""
        print(f"{row['value']:>8g} {row['controller']:>10} {row['median']:>7g} {row['mean']:>7.2f} "
              f"{row['failures']:>5}/{row['runs']:<3} {row['wall_s']:>7.0f} {p:>9}", flush=True)


if __name__ == "__main__":
    main()
