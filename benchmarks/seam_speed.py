"""The task seam's speed: the network kernel alone, the paper's cart-pole through the seam, and a
plant written here against the public seam only, side by side in one process.

    python benchmarks/seam_speed.py                 # R x P = 150 and 9000, N = 8, one thread
    python benchmarks/seam_speed.py --points 9000x8,9000x32 --steps 100 --repeats 5

Workload per point: ``R x P`` random recurrent spiking networks of ``N`` nodes (connection
probability 0.4), ``--steps`` control steps of 20 substeps (0.5 ms) each, every row running the
whole episode (failure limits lifted), one episode per network.

- ``kernel alone``: ``PopulationRecurrentIzhikevich.control_step`` on a fixed input current,
  the same networks, batch and substeps: what the closed loops are measured against.
- ``cart-pole (seam)``: ``TaskFitness``'s path, ``rollout(CartPoleTask.nonmarkov(), controller)``.
- ``pendulum (seam)``: ``Pendulum`` below, a plant that knows nothing of the toolkit but the
  ``Task`` base class.
- ``cart-pole, torch path`` (with ``--torch-path``): the seam with the network on the torch
  step, what runs without a C compiler (same results), to say how much slower that is.

Prints genome-steps/s, neuron-substeps/s and the ratio to the kernel alone (medians of
``--repeats``, interleaved so drift hits every path alike).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import torch
from scale import random_chunk  # noqa: E402 - the benchmarks' random networks (run from benchmarks/)

from evolution import Task, make_controller, rollout
from tasks.cartpole import CartPoleParams, CartPoleTask

SUBSTEPS = 20


class Pendulum(Task):
    """A torque-driven pendulum held near upright (theta = 0), observed as angle and rate."""

    name = "pendulum"
    observation_low, observation_high = (-math.pi, -8.0), (math.pi, 8.0)
    action_size, action_max, max_steps, control_period_s = 1, 2.0, 1000, 0.01
    fitness = "return"

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        theta = (torch.rand(batch, generator=generator, dtype=torch.float64) - 0.5) * 0.2
        return torch.stack([theta, torch.zeros_like(theta)], -1).to(device=device, dtype=dtype)

    def step(self, state, action):
        theta, omega = state.unbind(-1)
        omega = omega + self.control_period_s * (9.81 * torch.sin(theta) + 3.0 * action[:, 0])
        theta = theta + self.control_period_s * omega
        return torch.stack([theta, omega], -1), torch.cos(theta), torch.zeros_like(theta, dtype=torch.bool)

    def observe(self, state):
        return state


def time_kernel(controller, steps: int) -> float:
    net = controller.network
    B, n = controller.num_genomes, len(controller.nodes)
    i_ext = torch.full((B, n), 20.0)
    state = net.initial_state(i_ext)
    network = torch.arange(B)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, state = net.control_step(i_ext, state, substeps=SUBSTEPS, network=network)
    return time.perf_counter() - t0


def time_rollout(task, controller, steps: int) -> float:
    t0 = time.perf_counter()
    result = rollout(task, controller, max_steps=steps)
    elapsed = time.perf_counter() - t0
    assert int(result.steps.min()) == steps, "every row must run the whole episode"
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", default="150x8,9000x8", help="R x P 'x' N, comma separated")
    parser.add_argument("--steps", type=int, default=200, help="control steps per episode (default 200)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--torch-path", action="store_true", help="also time the torch path (no C compiler)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    points = [tuple(int(v) for v in p.lower().split("x")) for p in args.points.split(",")]
    cartpole = CartPoleTask.nonmarkov(plant=CartPoleParams(x_limit=1e30, theta_limit=1e30))
    pendulum = Pendulum()
    print(f"{args.threads} thread(s), {args.steps} control steps x {SUBSTEPS} substeps of 0.5 ms, "
          f"medians of {args.repeats}")
    header = f"{'R x P':>8}{'N':>4}  {'path':<20}{'genome-steps/s':>16}{'neuron-substeps/s':>19}{'vs kernel':>11}"
    print(header)
    print("-" * len(header))
    for rows, n in points:
        genomes, cfg = random_chunk(rows, n, rows + n, "cpu")
        ctl = {name: make_controller(genomes, cfg, task) for name, task in (("cartpole", cartpole),
                                                                               ("pendulum", pendulum))}
        ctl["torch"] = make_controller(genomes, cfg, cartpole, backend="torch")
        time_rollout(cartpole, ctl["cartpole"], 2)  # warm-up: kernel build, first calls
        runs: dict[str, list[float]] = {"kernel alone": [], "cart-pole (seam)": [], "pendulum (seam)": []}
        for _ in range(args.repeats):
            runs["kernel alone"].append(time_kernel(ctl["cartpole"], args.steps))
            runs["cart-pole (seam)"].append(time_rollout(cartpole, ctl["cartpole"], args.steps))
            runs["pendulum (seam)"].append(time_rollout(pendulum, ctl["pendulum"], args.steps))
            if args.torch_path:
                runs.setdefault("cart-pole, torch path", []).append(time_rollout(cartpole, ctl["torch"], args.steps))
        kernel = statistics.median(runs["kernel alone"])
        for name, times in runs.items():
            rate = rows * args.steps / statistics.median(times)
            print(f"{rows:>8}{n:>4}  {name:<20}{rate:>16.3g}{rate * n * SUBSTEPS:>19.3g}"
                  f"{kernel / statistics.median(times):>10.2f}x")


if __name__ == "__main__":
    main()
