"""A gymnasium environment through the seam (``tasks.gym_adapter.GymTask``) beside a torch port of
the same plant through the seam, side by side in one process.

    python benchmarks/gym_speed.py                  # 150 genomes, 200-step episodes, one thread
    python benchmarks/gym_speed.py --genomes 1000 --repeats 5

Both run the same random NEAT-SNN population (4 inputs, one output) on a cart-pole: gymnasium's
``CartPole-v1`` (Python, one environment per row) and ``tasks.cartpole.CartPoleTask`` with all
four variables observed and a 0.02 s step (the same Barto equations, in batched torch). Episodes
end on failure, so the rate counts the control steps actually simulated: genome-steps/s, medians
of ``--repeats``, interleaved.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution import NEAT, make_controller, rollout, spiking_config
from tasks.cartpole import CartPoleTask
from tasks.gym_adapter import GymTask

BOUNDS = ((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))


def timed(task, genomes, cfg, steps: int) -> tuple[float, int]:
    controller = make_controller(genomes, cfg, task)
    t0 = time.perf_counter()
    result = rollout(task, controller, max_steps=steps, seed=0)
    return time.perf_counter() - t0, int(result.steps.sum() + result.terminated.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--genomes", type=int, default=150)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = spiking_config(num_inputs=4, num_outputs=1, pop_size=args.genomes, max_hidden=4)
    neat = NEAT(cfg, seeds=[0])
    neat.run(lambda g: torch.rand(1, args.genomes, dtype=torch.float64), 5)  # some structure, random selection
    genomes = neat.ask()
    tasks = {"gymnasium CartPole-v1": GymTask("CartPole-v1", observation_bounds=BOUNDS, max_steps=args.steps),
             "torch port (seam)": CartPoleTask((0, 1, 2, 3), tau_s=0.02, max_steps=args.steps)}
    for task in tasks.values():
        timed(task, genomes, cfg, 2)  # warm-up: kernels, first calls
    rates: dict[str, list[float]] = {name: [] for name in tasks}
    for _ in range(args.repeats):
        for name, task in tasks.items():
            seconds, steps = timed(task, genomes, cfg, args.steps)
            rates[name].append(steps / seconds)
    print(f"{args.genomes} genomes, episodes of up to {args.steps} steps, one thread, medians of {args.repeats}")
    print(f"{'path':<24}{'genome-steps/s':>16}{'vs torch port':>15}")
    port = statistics.median(rates["torch port (seam)"])
    for name, r in rates.items():
        print(f"{name:<24}{statistics.median(r):>16.3g}{statistics.median(r) / port:>14.2f}x")


if __name__ == "__main__":
    main()
