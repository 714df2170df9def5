"""gymnasium's classic-control environments through the seam: the adapter (``GymTask(id,
adapter=True)``: one gymnasium environment per row, stepped in Python) beside the batched torch
port with its native step (``GymTask(id)``), in one process, one thread.

    python benchmarks/gym_speed.py                 # 150 and 9000 rows, 200-step episodes, 3 repeats
    python benchmarks/gym_speed.py --quick         # a smoke run: 20 steps, 1 repeat, adapter on 150 rows
    python benchmarks/gym_speed.py --rows 150 1000 --adapter-rows 500 --repeats 5

Every environment runs the same kind of population: random NEAT-SNN genomes
(``evolution.random_genomes``: 2 hidden neurons, half the possible connections) with the
``SpikingSpec`` defaults, one episode per genome (a row), from the task's seeded starts. Episodes
end on termination or after ``--steps``, so the rate counts the control steps actually simulated:
genome-steps/s, the median of ``--repeats``, the two paths interleaved. The adapter's cost is a
Python call per environment per step, so its rate hardly depends on the batch: it runs on at most
``--adapter-rows`` rows (the table says how many it ran on), as 9000 gymnasium environments
would take minutes per repeat.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution import SpikingSpec, make_controller, random_genomes, rollout, task_config
from tasks.gym_adapter import PORTS, GymTask

CARTPOLE_BOUNDS = ((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))  # gymnasium's velocities are unbounded


def timed(task, rows: int, steps: int) -> tuple[float, int]:
    """``(seconds, genome-steps)`` of one rollout of ``rows`` random genomes on ``task``."""
    cfg = task_config(task, "snn", pop_size=rows)
    controller = make_controller(random_genomes(cfg, hidden=2, density=0.5, seed=0), cfg, task, SpikingSpec())
    t0 = time.perf_counter()
    result = rollout(task, controller, max_steps=steps, seed=0)
    return time.perf_counter() - t0, int(result.steps.sum() + result.terminated.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[150, 9000], help="genomes (one episode each)")
    parser.add_argument("--steps", type=int, default=200, help="most control steps per episode")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--adapter-rows", type=int, default=1500, help="most rows the adapter runs on")
    parser.add_argument("--quick", action="store_true", help="20 steps, 1 repeat, the adapter on 150 rows")
    args = parser.parse_args()
    if args.quick:
        args.steps, args.repeats, args.adapter_rows = 20, 1, 150
    torch.set_num_threads(1)
    print(f"random NEAT-SNN genomes, one episode each, up to {args.steps} steps, one thread, "
          f"medians of {args.repeats}; genome-steps/s")
    print("| environment | rows | adapter | adapter rows | port | port / adapter |")
    print("|---|---|---|---|---|---|")
    for env_id in PORTS:
        bounds = {"observation_bounds": CARTPOLE_BOUNDS} if env_id == "CartPole-v1" else {}
        port = GymTask(env_id, **bounds)
        coding = {"discrete_actions": "bins"} if port.discrete else {}  # the port's action coding: one network
        paths = {"adapter": GymTask(env_id, adapter=True, **coding, **bounds), "port": port}
        for rows in args.rows:
            sizes = {"adapter": min(rows, args.adapter_rows), "port": rows}
            for name, task in paths.items():
                timed(task, min(sizes[name], 8), 2)  # warm-up: kernels, native builds, first calls
            rates: dict[str, list[float]] = {name: [] for name in paths}
            for _ in range(args.repeats):
                for name, task in paths.items():
                    seconds, steps = timed(task, sizes[name], args.steps)
                    rates[name].append(steps / seconds)
            adapter, port = (statistics.median(rates[name]) for name in ("adapter", "port"))
            print(f"| {env_id} | {rows} | {adapter:.3g} | {sizes['adapter']} | {port:.3g} | {port / adapter:.0f}x |")


if __name__ == "__main__":
    main()
