"""The library's defaults on plants they were never tuned on: four small control problems
written for this check, each with a hand-made reference controller that sets its threshold.

    python benchmarks/unseen_plants.py                                   # all, seeds 0 1, 40 generations
    python benchmarks/unseen_plants.py --plants Reacher2D --methods sigmoid pgpe --generations 150

The plants (``evolution.Task`` subclasses below, each runnable as ``snn-neat evolve
unseen_plants:NAME`` from this folder) differ from the five classic-control environments in
what they ask of a controller:

* ``DoubleIntegrator``: a 1 kg mass on a line, force in [-1, 1] N, regulate x to 0 m from random
  starts (a cost per step of x^2 + 0.1 v^2 + 0.01 u^2); reference: a PD law, -4 x - 3 v.
* ``LongPoleCart``: a cart-pole with a 1 m half-length pole (twice gymnasium's), a continuous
  force in [-10, 10] N, balance for 500 steps of 0.02 s (fitness: steps); reference: a linear
  state feedback.
* ``Reacher2D``: a kinematic two-link arm (links 0.5 m), two joint speeds in [-2, 2] rad/s,
  bring the tip to a random target (a cost of the distance, m, per step): two outputs, and a
  law that multiplies inputs (the Jacobian transpose); reference: 10 J^T (target - tip).
* ``HeaterLag``: three first-order lags in series (2 s each), heater power in [-1, 1], track a
  random set point (a cost of |error| per step of 0.1 s); reference: the set point plus 1 x the
  error.

Each threshold is the reference's mean return on 200 episodes rounded towards the zero action's,
so a run that reaches it controls about as well as the hand-made law; ``tests/
test_unseen_plants.py`` checks that the references reach them and the zero action does not.
Methods: ``sigmoid`` and ``snn`` are ``snn-neat evolve`` with nothing set but the plant, the
controller and a budget of ``--generations``' training episodes (``classic_control_vs_es.run_ours``);
``pgpe`` is the
evolution-strategy peer of ``benchmarks/classic_control_vs_es.py`` (EvoTorch's PGPE with its
settings there, an obs-16-act tanh MLP) on the same number of training episodes, its final
centre tested on the same 100 fresh episodes. One thread; CPU seconds are ``process_time``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))  # es_peers, classic_control_vs_es

from classic_control_vs_es import run_ours  # noqa: E402

from evolution.defaults import default_episodes  # noqa: E402
from evolution.phenotype import task_config  # noqa: E402
from evolution.task import Task  # noqa: E402

__all__ = ["DoubleIntegrator", "LongPoleCart", "Reacher2D", "HeaterLag", "PLANTS", "REFERENCES", "zero_action",
           "policy_returns", "run_pgpe", "main"]


def _uniform(batch: int, generator: torch.Generator, half_widths: list[float]) -> torch.Tensor:
    """``[batch, len(half_widths)]`` float64, each column uniform in [-h, h)."""
    h = torch.tensor(half_widths, dtype=torch.float64)
    return (torch.rand(batch, len(half_widths), generator=generator, dtype=torch.float64) * 2.0 - 1.0) * h


class DoubleIntegrator(Task):
    """A 1 kg mass on a frictionless line: state (x (m), v (m/s)), force u in [-1, 1] N, a step
    of 0.05 s, 200 steps; reward -(x^2 + 0.1 v^2 + 0.01 u^2). Starts: x in [-1.5, 1.5) m, v in
    [-1, 1) m/s."""

    name = "double-integrator"
    observation_low, observation_high = (-2.0, -2.0), (2.0, 2.0)
    action_size, action_max, max_steps, control_period_s = 1, 1.0, 200, 0.05
    reward_threshold = -25.0

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        return _uniform(batch, generator, [1.5, 1.0]).to(device=device, dtype=dtype)

    def step(self, state, action):
        u = action[:, 0].clamp(-1.0, 1.0)
        x, v = state.unbind(-1)
        v = v + u * 0.05
        x = x + v * 0.05
        reward = -(x * x + 0.1 * v * v + 0.01 * u * u)
        return torch.stack([x, v], -1), reward, torch.zeros_like(reward, dtype=torch.bool)

    def observe(self, state):
        return state


class LongPoleCart(Task):
    """A cart-pole (cart 1 kg, pole 0.2 kg of half-length 1 m, g = 9.8 m/s^2; gymnasium's
    equations, Euler steps of 0.02 s) pushed by a force in [-10, 10] N; fails past 2.4 m or
    0.21 rad; fitness: steps balanced, of 500. Starts: every state variable in [-0.08, 0.08)."""

    name = "long-pole-cart"
    observation_low, observation_high = (-2.4, -3.0, -0.3, -3.0), (2.4, 3.0, 0.3, 3.0)
    action_size, action_max, max_steps, control_period_s = 1, 10.0, 500, 0.02
    fitness = "steps"
    reward_threshold = 475.0

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        return _uniform(batch, generator, [0.08] * 4).to(device=device, dtype=dtype)

    def step(self, state, action):
        force = action[:, 0].clamp(-10.0, 10.0)
        x, x_dot, theta, theta_dot = state.unbind(-1)
        gravity, cart, pole, half_length, dt = 9.8, 1.0, 0.2, 1.0, 0.02
        total = cart + pole
        cos, sin = torch.cos(theta), torch.sin(theta)
        temp = (force + pole * half_length * theta_dot * theta_dot * sin) / total
        theta_acc = (gravity * sin - cos * temp) / (half_length * (4.0 / 3.0 - pole * cos * cos / total))
        x_acc = temp - pole * half_length * theta_acc * cos / total
        x, x_dot = x + dt * x_dot, x_dot + dt * x_acc
        theta, theta_dot = theta + dt * theta_dot, theta_dot + dt * theta_acc
        failed = (x.abs() > 2.4) | (theta.abs() > 0.21)
        return torch.stack([x, x_dot, theta, theta_dot], -1), torch.ones_like(x), failed

    def observe(self, state):
        return state


class Reacher2D(Task):
    """A kinematic two-link planar arm (links 0.5 m from the origin): state (q1, q2 (rad), the
    target's x, y (m)); actions: the joint speeds in [-2, 2] rad/s for 0.05 s; 100 steps; reward
    -|tip - target| (m). Observes cos q1, sin q1, cos q2, sin q2, the target and target - tip.
    Starts: joints uniform in [-pi, pi), the target at 0.25 to 0.95 m in any direction."""

    name = "reacher-2d"
    observation_low, observation_high = (-1.0,) * 6 + (-2.0, -2.0), (1.0,) * 6 + (2.0, 2.0)
    action_size, action_max, max_steps, control_period_s = 2, 2.0, 100, 0.05
    reward_threshold = -22.0

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        joints = _uniform(batch, generator, [math.pi, math.pi])
        radius = 0.25 + 0.7 * torch.rand(batch, generator=generator, dtype=torch.float64)
        angle = _uniform(batch, generator, [math.pi])[:, 0]
        target = torch.stack([radius * torch.cos(angle), radius * torch.sin(angle)], -1)
        return torch.cat([joints, target], -1).to(device=device, dtype=dtype)

    @staticmethod
    def tip(state: torch.Tensor) -> torch.Tensor:
        """``[B, 2]``: the arm's tip (m)."""
        q1, q12 = state[:, 0], state[:, 0] + state[:, 1]
        return 0.5 * torch.stack([torch.cos(q1) + torch.cos(q12), torch.sin(q1) + torch.sin(q12)], -1)

    def step(self, state, action):
        moved = torch.cat([state[:, :2] + action.clamp(-2.0, 2.0) * 0.05, state[:, 2:]], -1)
        distance = (self.tip(moved) - moved[:, 2:]).norm(dim=-1)
        return moved, -distance, torch.zeros_like(distance, dtype=torch.bool)

    def observe(self, state):
        q1, q2 = state[:, 0], state[:, 1]
        delta = state[:, 2:] - self.tip(state)
        return torch.stack([torch.cos(q1), torch.sin(q1), torch.cos(q2), torch.sin(q2), state[:, 2], state[:, 3],
                            delta[:, 0], delta[:, 1]], -1)


class HeaterLag(Task):
    """Three first-order lags in series, each with a time constant of 2 s, driven by a heater
    power in [-1, 1] (units of the set point); steps of 0.1 s, 200 steps; reward -|c - set point|
    for the last lag's output c. Observes the set point, c and their difference. Starts: all lags
    at 0, the set point in [-0.8, 0.8)."""

    name = "heater-lag"
    observation_low, observation_high = (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)
    action_size, action_max, max_steps, control_period_s = 1, 1.0, 200, 0.1
    reward_threshold = -20.0

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        set_point = _uniform(batch, generator, [0.8])
        return torch.cat([torch.zeros(batch, 3, dtype=torch.float64), set_point], -1).to(device=device, dtype=dtype)

    def step(self, state, action):
        power = action[:, 0].clamp(-1.0, 1.0)
        a, b, c, set_point = state.unbind(-1)
        rate = 0.1 / 2.0  # step / time constant
        a = a + rate * (power - a)
        b = b + rate * (a - b)
        c = c + rate * (b - c)
        reward = -(c - set_point).abs()
        return torch.stack([a, b, c, set_point], -1), reward, torch.zeros_like(reward, dtype=torch.bool)

    def observe(self, state):
        return torch.stack([state[:, 3], state[:, 2], state[:, 3] - state[:, 2]], -1)


def _reacher_reference(obs: torch.Tensor) -> torch.Tensor:
    c1, s1, c2, s2 = obs[:, 0], obs[:, 1], obs[:, 2], obs[:, 3]
    s12, c12 = s1 * c2 + c1 * s2, c1 * c2 - s1 * s2
    jacobian = 0.5 * torch.stack([torch.stack([-s1 - s12, -s12], -1), torch.stack([c1 + c12, c12], -1)], -2)
    return 10.0 * (jacobian.transpose(-1, -2) @ obs[:, 6:8].unsqueeze(-1)).squeeze(-1)


PLANTS = {cls.__name__: cls for cls in (DoubleIntegrator, LongPoleCart, Reacher2D, HeaterLag)}
# each plant's hand-made law: observations [B, n] -> actions [B, action_size] (before clipping)
REFERENCES = {
    "DoubleIntegrator": lambda obs: -4.0 * obs[:, :1] - 3.0 * obs[:, 1:2],
    "LongPoleCart": lambda obs: obs[:, :1] + 2.0 * obs[:, 1:2] + 40.0 * obs[:, 2:3] + 8.0 * obs[:, 3:4],
    "Reacher2D": _reacher_reference,
    "HeaterLag": lambda obs: obs[:, :1] + obs[:, 2:3],
}


def zero_action(obs: torch.Tensor, action_size: int) -> torch.Tensor:
    """No control: zeros ``[B, action_size]``."""
    return torch.zeros(obs.shape[0], action_size, dtype=obs.dtype)


def policy_returns(task: Task, policy, episodes: int = 200, seed: int = 0) -> torch.Tensor:
    """``[episodes]`` float64 returns (or steps, for ``fitness = "steps"``) of ``policy``
    (observations -> actions) on ``task`` from seeded starts."""
    state = task.reset(episodes, torch.Generator().manual_seed(seed), dtype=torch.float64)
    total = torch.zeros(episodes, dtype=torch.float64)
    alive = torch.ones(episodes, dtype=torch.bool)
    for _ in range(task.max_steps):
        action = policy(task.observe(state)).clamp(-task.action_max, task.action_max)
        state, reward, done = task.step(state, action)
        total += torch.where(alive, torch.ones_like(reward) if task.fitness == "steps" else reward, 0.0)
        alive &= ~done
        if not bool(alive.any()):
            break
    return total


def run_pgpe(plant: str, seed: int, budget_episodes: int) -> dict:
    """EvoTorch's PGPE as ``benchmarks/classic_control_vs_es.py`` sets it, on ``budget_episodes``
    training episodes; its final centre tested on the 100 test episodes our runs face."""
    from classic_control_vs_es import PGPE_SETTINGS, TRAIN_STREAM, _values
    from es_peers import MLP, PGPE, peer_returns

    from tasks.studies.threshold_runs import TEST_EPISODES, TEST_SEED

    task = PLANTS[plant]()
    s = _values(PGPE_SETTINGS)
    mlp = MLP.for_task(task, s["hidden_sizes"], s["hidden_activation"])
    algo = PGPE(mlp.num_params, popsize=s["popsize"], center_learning_rate=s["center_learning_rate"],
                max_speed=s["max_speed"], momentum=s["momentum"], radius_init=s["radius_init"],
                stdev_learning_rate=s["stdev_learning_rate"], stdev_max_change=s["stdev_max_change"], seed=seed)
    P, E = int(s["popsize"]), int(s["episodes_per_member"])
    stream = torch.Generator().manual_seed(TRAIN_STREAM + seed)
    cpu0 = time.process_time()
    for _ in range(max(1, budget_episodes // (P * E))):
        x = algo.ask()
        episode_seed = int(torch.randint(0, 2**62, (1,), generator=stream))
        algo.tell(x, peer_returns(task, mlp, x, episodes=E, seed=episode_seed, raw_observations=False).mean(1))
    test = peer_returns(task, mlp, algo.center.detach().to(torch.float32).unsqueeze(0), episodes=TEST_EPISODES,
                        seed=TEST_SEED + seed, raw_observations=False)[0]
    mean = float(test.mean())
    return {"plant": plant, "method": "pgpe", "seed": seed, "threshold": task.reward_threshold,
            "episodes": budget_episodes, "cpu_s": time.process_time() - cpu0, "generation": -1,
            "test_mean": mean, "test_reaches": mean >= task.reward_threshold}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--plants", nargs="+", default=list(PLANTS), choices=list(PLANTS), metavar="PLANT")
    p.add_argument("--methods", nargs="+", default=["sigmoid", "snn", "pgpe"], choices=["sigmoid", "snn", "pgpe"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    p.add_argument("--generations", type=int, default=40, help="NEAT generations per run (default 40); PGPE gets "
                                                               "as many training episodes")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    print("| plant | threshold | reference | zero action | method | reached (test) | test means | CPU-s per run |")
    print("|---|---|---|---|---|---|---|---|")
    for plant in args.plants:
        task = PLANTS[plant]()
        reference = float(policy_returns(task, REFERENCES[plant]).mean())
        zero = float(policy_returns(task, lambda obs, n=task.action_size: zero_action(obs, n)).mean())
        for method in args.methods:
            records = []
            for seed in args.seeds:
                # the training episodes a NEAT run of --generations has
                budget = args.generations * task_config(task, "sigmoid").pop_size * default_episodes(task)
                if method == "pgpe":
                    records.append(run_pgpe(plant, seed, budget))
                else:  # snn-neat evolve unseen_plants:PLANT --controller METHOD --seed S --episodes BUDGET
                    records.append(run_ours(method, f"unseen_plants:{plant}", seed, budget)[0])
            reached = sum(r["test_reaches"] for r in records)
            means = ", ".join(f"{r['test_mean']:.1f}" for r in records)
            cpu = statistics.median(r["cpu_s"] for r in records)
            print(f"| {plant} | {task.reward_threshold:g} | {reference:.1f} | {zero:.1f} | {method} | "
                  f"{reached}/{len(records)} | {means} | {cpu:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
