"""Ray's per-task overhead, and cart-pole evaluations run locally vs. as Ray tasks.

Starts a private local Ray (``ray.init(address="local", num_cpus=--cpus)``) and prints a
table of medians over ``--repeats``:

- empty remote task, one at a time: submit, wait, get (a full round trip);
- empty remote tasks, ``--burst`` in flight at once: amortised cost per task;
- ``--popsize`` spiking controllers of a fixed recurrent topology (``FixedTopologyProblem``)
  x ``--starts`` start states x up to ``--max-steps`` control steps: one batch in this
  process (the package's usual way, ``--threads`` torch threads, and again with ``--cpus``
  threads), vs. split into ``--tasks`` Ray tasks of one CPU each (workers warmed up first, so
  no process start-up is timed).

    python benchmarks/ray_overhead.py            # default sizes
    python benchmarks/ray_overhead.py --quick    # a smoke run

What it means for a real cluster: a Ray task costs a fixed overhead (scheduling,
serialisation, the round trip) on top of its work; on a cluster add the network round trip
(~0.1-1 ms on a LAN) and the transfer of its arguments (here kilobytes of weights). Send work
in pieces that run for seconds or more, whole NEAT runs or large population shards, so the
overhead stays below 1 %; shards of milliseconds are slower than evaluating the batch in one
process. Cart-pole evaluations are independent, so throughput then grows with the cluster's
CPUs (or GPUs) until the driver's own per-generation work (selection, reproduction) dominates.
Timings on a shared machine are noisy; compare ratios rather than absolute numbers.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution.weight_search import FixedTopologyProblem
from tasks.cartpole import CartPoleTask
from tasks.studies.cartpole import controller_config
from tasks.studies.generalization import start_grid


def _problem(starts: int, max_steps: int) -> FixedTopologyProblem:
    cfg = controller_config("snn", max_hidden=4)
    N, out = cfg.num_nodes, cfg.first_output
    mask = torch.zeros(N, N, dtype=torch.bool)
    mask[:2, out] = True
    mask[:2, out + 1 : out + 3] = True  # inputs -> two hidden
    mask[out + 1 : out + 3, out] = True  # hidden -> output
    mask[out, out + 3] = mask[out + 3, out] = True  # a recurrent loop through the output
    grid = start_grid()
    pick = torch.randperm(grid.shape[0], generator=torch.Generator().manual_seed(0))[:starts]
    return FixedTopologyProblem(cfg, mask, task=CartPoleTask.nonmarkov(), starts=grid[pick], max_steps=max_steps)


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cpus", type=int, default=2, help="CPUs of the local Ray")
    ap.add_argument("--tasks", type=int, default=2, help="Ray tasks the cart-pole batch is split into")
    ap.add_argument("--popsize", type=int, default=128)
    ap.add_argument("--starts", type=int, default=25)
    ap.add_argument("--max-steps", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1, help="torch threads of the local evaluation")
    ap.add_argument("--roundtrips", type=int, default=200, help="empty tasks timed one by one")
    ap.add_argument("--burst", type=int, default=1000, help="empty tasks in flight at once")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="small sizes, a smoke run")
    args = ap.parse_args(argv)
    if args.quick:
        args.popsize, args.starts, args.max_steps = 16, 2, 100
        args.roundtrips, args.burst, args.repeats = 50, 200, 3

    import ray

    torch.set_num_threads(args.threads)
    ray.init(address="local", num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    try:
        @ray.remote(num_cpus=1)
        def noop():
            return None

        @ray.remote(num_cpus=1)
        def evaluate(problem: FixedTopologyProblem, values: torch.Tensor) -> torch.Tensor:
            torch.set_num_threads(1)
            return problem.fitness(values)

        ray.get([noop.remote() for _ in range(4 * args.cpus)])  # start the workers
        rt = [0.0] * args.roundtrips
        for i in range(args.roundtrips):
            start = time.perf_counter()
            ray.get(noop.remote())
            rt[i] = time.perf_counter() - start
        roundtrip = statistics.median(rt)
        burst = _median_time(lambda: ray.get([noop.remote() for _ in range(args.burst)]), args.repeats) / args.burst

        problem = _problem(args.starts, args.max_steps)
        noise = torch.randn(args.popsize, problem.solution_length, generator=torch.Generator().manual_seed(1))
        values = problem.initial_solution() + noise  # the same random controllers every run
        problem_ref = ray.put(problem)
        chunks = list(values.chunk(args.tasks))

        def run_local():
            return problem.fitness(values)

        def run_ray():
            return torch.cat(ray.get([evaluate.remote(problem_ref, c) for c in chunks]))

        local_fit, ray_fit = run_local(), run_ray()  # warm-up, and a check
        mismatches = int((local_fit != ray_fit).sum())
        local = _median_time(run_local, args.repeats)
        remote = _median_time(run_ray, args.repeats)
        torch.set_num_threads(args.cpus)
        local_mt = _median_time(run_local, args.repeats)
        torch.set_num_threads(args.threads)
        episodes = args.popsize * args.starts
        steps = int(local_fit.sum().item() * args.starts)  # control steps simulated in total
    finally:
        ray.shutdown()

    print(f"local Ray, {args.cpus} CPUs; medians of {args.repeats} repeats ({args.roundtrips} for the round trip)")
    print(f"{'measure':58s} {'local':>12s} {'ray':>12s} {'local/ray':>10s}")
    print(f"{'empty task, round trip (ms)':58s} {'':>12s} {roundtrip * 1e3:12.3f} {'':>10s}")
    print(f"{f'empty task, {args.burst} in flight, per task (ms)':58s} {'':>12s} {burst * 1e3:12.3f} {'':>10s}")
    what = f"cart-pole: {args.popsize} SNNs x {args.starts} starts, <= {args.max_steps} steps (s)"
    print(f"{what:58s} {local:12.3f} {remote:12.3f} {local / remote:10.2f}")
    what = f"  the same, local with {args.cpus} torch threads (s)"
    print(f"{what:58s} {local_mt:12.3f} {remote:12.3f} {local_mt / remote:10.2f}")
    print(f"{'  episodes/s':58s} {episodes / local:12.1f} {episodes / remote:12.1f} {local / remote:10.2f}")
    print(f"{'  control steps/s (all episodes together)':58s} {steps / local:12.0f} {steps / remote:12.0f} "
          f"{local / remote:10.2f}")
    print(f"fitness of the Ray shards equal to the local batch's: {args.popsize - mismatches} of {args.popsize}")
    print(f"(local: one batch, {args.threads} torch thread(s); ray: {args.tasks} tasks of 1 CPU; "
          f"local/ray > 1 means Ray is faster)")


if __name__ == "__main__":
    main()
