"""A small reproduction run locally (one batch) and as Ray shards on this machine.

Starts a private local Ray (``ray.init(address="local", num_cpus=--cpus)``) and times
``--runs`` seeded runs of ``--controller`` on ``--table`` for ``--generations`` generations:

- local, one batch, 1 torch thread and ``--cpus`` torch threads (``run_controller``);
- through Ray, ``--cpus`` shards of one CPU each (``run_controllers_on_ray``), first with
  fresh workers (each imports torch and the package: the cold start a cluster pays once
  per worker), then again with the workers warm;
- Ray's round trip for an empty task (the fixed per-task cost; ``ray_overhead.py`` has more).

and checks that the Ray results equal the local ones.

    python benchmarks/distributed_reproduce.py            # default sizes (~1-2 min)
    python benchmarks/distributed_reproduce.py --quick    # a smoke run

What it means for a real cluster: a shard is a whole NEAT run (or several), seconds to
hours of work, so Ray's per-task cost (about a millisecond, plus the network) is
negligible; what remains is the worker cold start (seconds, once per worker) and the
driver's wait for the slowest shard. On this 2-CPU machine, shards compete with each other
for the same cores a multi-threaded local batch would use, so expect a ratio near 1; on a
cluster with C CPUs, the paper's 60 runs per controller split into up to 60 shards, and the
wall time falls towards that of the slowest single run, a speed-up of up to min(C, 120)
over one single-threaded process (fewer where runs solve early and shards are unequal).
Timings on a shared machine are noisy; compare ratios rather than absolute numbers.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import torch

from tasks.studies.distributed import run_controllers_on_ray
from tasks.studies.reproduce import run_controller


def _same(a, b) -> bool:
    return (a.solved_generation == b.solved_generation and a.best_fitness == b.best_fitness
            and torch.equal(a.history, b.history)
            and all(torch.equal(t, getattr(b.champions, k)) for k, t in a.champions.tensors().items()))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--table", choices=["table1", "table2"], default="table2")
    ap.add_argument("--controller", choices=["snn", "sigmoid"], default="sigmoid")
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--generations", type=int, default=10)
    ap.add_argument("--cpus", type=int, default=2, help="CPUs of the local Ray, and its shards")
    ap.add_argument("--quick", action="store_true", help="small sizes, a smoke run")
    args = ap.parse_args(argv)
    if args.quick:
        args.runs, args.generations = 4, 3

    import ray

    seeds = list(range(args.runs))
    scratch = Path(tempfile.mkdtemp(prefix="distributed_reproduce_"))
    times: dict[str, float] = {}

    def timed(name, fn):
        start = time.perf_counter()
        value = fn()
        times[name] = time.perf_counter() - start
        return value

    try:
        torch.set_num_threads(1)
        local = timed("local1", lambda: run_controller(args.table, args.controller, seeds, args.generations,
                                                       scratch / "local1", progress=False))
        torch.set_num_threads(args.cpus)
        timed("localN", lambda: run_controller(args.table, args.controller, seeds, args.generations,
                                               scratch / "localN", progress=False))
        torch.set_num_threads(1)
        ray.init(address="local", num_cpus=args.cpus, include_dashboard=False, log_to_driver=False,
                 logging_level="ERROR")
        try:
            def on_ray(name):
                return run_controllers_on_ray(args.table, [args.controller], seeds, args.generations, scratch / name,
                                              address="local", shards=args.cpus, progress=False)[args.controller]

            cold = timed("ray_cold", lambda: on_ray("ray_cold"))
            warm = timed("ray_warm", lambda: on_ray("ray_warm"))

            @ray.remote(num_cpus=1)
            def noop():
                return None

            ray.get(noop.remote())
            rt = []
            for _ in range(100):
                start = time.perf_counter()
                ray.get(noop.remote())
                rt.append(time.perf_counter() - start)
            roundtrip = statistics.median(rt)
        finally:
            ray.shutdown()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    base = times["local1"]
    gens = sum(g if g > 0 else args.generations for g in local.solved_generation)  # generations evaluated
    print(f"{args.table} {args.controller}: {args.runs} runs x <= {args.generations} generations "
          f"({gens} run-generations), local Ray with {args.cpus} CPUs, {args.cpus} shards")
    print(f"{'measure':44s} {'wall (s)':>9s} {'run-gens/s':>11s} {'speed-up':>9s}")
    rows = [("local, one batch, 1 torch thread", "local1"),
            (f"local, one batch, {args.cpus} torch threads", "localN"),
            (f"ray, {args.cpus} shards, cold workers", "ray_cold"),
            (f"ray, {args.cpus} shards, warm workers", "ray_warm")]
    for label, key in rows:
        print(f"{label:44s} {times[key]:9.2f} {gens / times[key]:11.1f} {base / times[key]:9.2f}")
    print(f"{'ray empty task round trip (ms)':44s} {roundtrip * 1e3:9.3f}")
    print(f"Ray results equal to the local batch: cold {_same(cold, local)}, warm {_same(warm, local)}")
    print("(speed-up: local one-thread wall time / this wall time; > 1 means faster)")


if __name__ == "__main__":
    main()
