"""Time to a solution: what a control step costs at batch 1 and in a wide batch, and what whole
studies cost in CPU seconds, in one run and one table.

    python benchmarks/time_to_solution.py                       # everything (about 10 minutes here)
    python benchmarks/time_to_solution.py --parts steps,table2  # a subset
    python benchmarks/time_to_solution.py --dp-runs 20          # DPV / DPNV over seeds 0-19

Parts:
- ``steps``: the paper's non-Markov cart-pole through the public seam (``rollout``), random
  networks of 8 nodes whose plant never fails (failure limits lifted), one thread. A long
  episode of one row (``--long-steps`` control steps) against 9000 rows for 200 steps: microseconds
  per control step at batch 1 against per row-step in the batch, and their ratio, for NEAT-SNN and
  sigmoid NEAT, natively (``evolution.kernels.episodes``) and through the Python loop (``native=False``);
  and NEAT-SNN natively on Table I's task (Bernoulli-coded inputs, random two-hidden networks).
- ``table2``, ``table1``: ``snn-neat reproduce table2|table1 --runs 60`` with the default settings,
  as a user runs it: wall and CPU seconds (this process's children).
- ``dpv``, ``dpnv``: ``snn-neat reproduce dpv|dpnv --runs N --no-generalization`` (seeds
  0..N-1; the evolution with NEAT 2002's solve test, which for DPNV includes the 625-start
  test of each generation's champion, but not the report's extra tests of every champion, which
  NEAT C++ does not run): CPU seconds per run and per solved run, beside NEAT C++ 1.2.1's on
  this machine kind (0.39 s per solved DPV run, 5.0 s per solved DPNV run; issue 28's
  measurement).

Studies run in a temporary folder (or ``--keep DIR``); medians of ``--repeats`` for the step
costs, interleaved so drift hits every path alike.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from scale import random_chunk  # noqa: E402 - the benchmarks' random networks (run from benchmarks/)

from evolution import make_controller, random_genomes, rollout
from tasks.cartpole import CartPoleParams, CartPoleTask
from tasks.studies.cartpole import paper_task, study_config, study_spec

PARTS = ("steps", "table2", "table1", "dpv", "dpnv")
NEAT_CPP_PER_SOLVED_RUN_S = {"dpv": 0.39, "dpnv": 5.0}  # NEAT C++ 1.2.1 on this machine kind (issue 28)


def _costs(task, ctl1, ctl9, n1: int, repeats: int, native: bool = True) -> tuple[float, float]:
    """Medians over ``repeats`` of us per control step of ``ctl1`` (one genome, ``n1`` steps) and
    us per row-step of ``ctl9`` (9000 genomes, 200 steps), interleaved."""
    t1, t9 = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = rollout(task, ctl1, max_steps=n1, native=native)
        t1.append((time.perf_counter() - t0) / n1)
        t0 = time.perf_counter()
        r9 = rollout(task, ctl9, max_steps=200, native=native)
        t9.append((time.perf_counter() - t0) / (200 * 9000))
        assert int(r.steps.min()) == n1 and int(r9.steps.min()) == 200, "every row runs the whole episode"
    return statistics.median(t1) * 1e6, statistics.median(t9) * 1e6


def _step_costs(long_steps: int, repeats: int) -> list[tuple[str, str, float, float]]:
    """``(controller, path, us per step at batch 1, us per row-step at 9000 rows)``."""
    task = CartPoleTask.nonmarkov(plant=CartPoleParams(x_limit=1e30, theta_limit=1e30))
    two, cfg = random_chunk(2, 8, 7, "cpu")
    one = two.gather(torch.zeros(1, 1, dtype=torch.int64))  # one genome: NEATConfig needs populations of 2
    wide, _ = random_chunk(9000, 8, 9008, "cpu")
    out = []
    for kind in ("snn", "sigmoid"):
        ctl1 = make_controller(one, cfg, task, kind)
        ctl9 = make_controller(wide, cfg, task, kind)
        rollout(task, ctl1, max_steps=2)  # builds and binds the kernels
        for native, path in ((True, "native episodes"), (False, "Python loop")):
            n1 = long_steps if native else max(long_steps // 20, 200)
            out.append((kind, path, *_costs(task, ctl1, ctl9, n1, repeats, native)))
    out.append(("snn, Table I's Bernoulli inputs", "native episodes", *_table1_step_costs(long_steps, repeats)))
    return out


def _table1_step_costs(long_steps: int, repeats: int) -> tuple[float, float]:
    """``_costs`` for NEAT-SNN on Table I (Bernoulli-coded inputs, 40 substeps per control step):
    random two-hidden networks of its study config, failure limits lifted."""
    task = paper_task("table1", plant=CartPoleParams(x_limit=1e30, theta_limit=1e30))
    spec, cfg = study_spec("table1", "snn"), study_config("table1", "snn")
    wide = random_genomes(dataclasses.replace(cfg, pop_size=9000), hidden=2, density=0.5, seed=0)
    one = wide.gather(torch.zeros(1, 1, dtype=torch.int64))
    ctl1, ctl9 = make_controller(one, cfg, task, spec), make_controller(wide, cfg, task, spec)
    rollout(task, ctl1, max_steps=2)
    return _costs(task, ctl1, ctl9, long_steps, repeats)


def _study(args: list[str], folder: Path) -> tuple[float, float, dict]:
    """Wall and CPU seconds of ``snn-neat reproduce ARGS --out folder``, and its summary.json."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "tasks.studies.cli", "reproduce", *args, "--out", str(folder), "--quiet"],
                   check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    summary = folder / "summary.json"
    return wall, cpu, json.loads(summary.read_text()) if summary.exists() else {}


def _solved(summary: dict, controller: str) -> int | None:
    """Solved runs of ``controller`` in a report's summary.json (tables count failures instead)."""
    row = summary.get("rows", {}).get(controller)
    if not row:
        return None
    return int(row["solved"]) if "solved" in row else int(row["runs"]) - int(row["failures"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma separated, of {', '.join(PARTS)}")
    parser.add_argument("--long-steps", type=int, default=20_000, help="control steps of the batch-1 episode")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--dp-runs", type=int, default=10, help="seeds 0..N-1 of the double-pole studies")
    parser.add_argument("--keep", default=None, help="write the studies here instead of a temporary folder")
    args = parser.parse_args()
    parts = [p for p in args.parts.split(",") if p]
    if any(p not in PARTS for p in parts):
        parser.error(f"--parts must list some of {PARTS}")
    rows: list[str] = []
    if "steps" in parts:
        torch.set_num_threads(1)
        rows.append("| step cost, one thread | path | batch 1 (us/step) | 9000 rows (us/row-step) | ratio |")
        rows.append("|---|---|---|---|---|")
        for kind, path, us1, us9 in _step_costs(args.long_steps, args.repeats):
            rows.append(f"| {kind} | {path} | {us1:.2f} | {us9:.3f} | {us1 / us9:.1f}x |")
    studies = [p for p in parts if p != "steps"]
    if studies:
        root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="time_to_solution_"))
        root.mkdir(parents=True, exist_ok=True)
        rows.append("")
        rows.append("| study | command | wall (s) | CPU (s) | CPU per run (s) | CPU per solved run (s) | NEAT C++ 1.2.1 |")
        rows.append("|---|---|---|---|---|---|---|")
        for study in studies:
            if study in ("table2", "table1"):
                cmd = [study, "--runs", "60"]
                runs = 120
            else:
                cmd = [study, "--runs", str(args.dp_runs), "--no-generalization"]
                runs = 2 * args.dp_runs
            wall, cpu, summary = _study(cmd, root / study)
            solved = [_solved(summary, c) for c in ("snn", "sigmoid")]
            per_solved = "" if None in solved or not sum(solved) else f"{cpu / sum(solved):.2f}"
            ref = f"{NEAT_CPP_PER_SOLVED_RUN_S[study]} per solved run" if study in NEAT_CPP_PER_SOLVED_RUN_S else ""
            rows.append(f"| {study} | snn-neat reproduce {' '.join(cmd)} | {wall:.1f} | {cpu:.1f} | {cpu / runs:.2f} "
                        f"| {per_solved} | {ref} |")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} thread(s) here; studies with their default threads")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
