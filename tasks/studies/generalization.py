"""Generalisation tests: Gruau et al.'s 625 start states, for the cart-pole and the double pole.

Gruau, Whitley & Pyeatt (1996) test a pole balancer beyond the single start it was evolved
on: each of the four state variables takes 0.05, 0.25, 0.5, 0.75 and 0.95 of its range, all
5^4 = 625 combinations, and the network must balance for 1000 steps from each. Their ranges
(as Stanley & Miikkulainen 2002 report them): x in +-2.16 m, x_dot in +-1.35 m/s, theta in
+-3.6 degrees, theta_dot in +-8.6 degrees/s. The fractions of a range ``[-a, a]`` are the
values ``a * (2 f - 1)`` = ``a * (-0.9, -0.5, 0, 0.5, 0.9)``.

Scaled to this plant (``CartPoleParams``): x keeps 0.9 of the track half-length (2.16 m of
2.4 m, Gruau's own track), theta keeps 0.3 of the failure angle (3.6 degrees of 12 degrees,
Gruau's absolute value; scaling his 3.6 of 36 degrees down to 1.2 degrees would make the test
easier than the paper's own 3-degree start, which this range contains), and the velocities
keep Gruau's absolute values. Every start lies strictly inside the failure limits.

A start counts as a success when the controller balances for ``steps`` control steps (default
1000, Gruau's; the paper's Table II task asks 5000).

Everything is batched: ``C`` controllers x ``S`` starts are one rollout of ``S`` episodes per
controller (``evolution.rollout``: row ``c * S + s`` runs controller ``c`` from start ``s``).

    from tasks.studies.generalization import start_grid, success_rate
    rate = success_rate(champion, config)  # [R, P]: fraction of the 625 starts balanced

The double pole's test (NEAT 2002's, ``generalization_starts`` and ``balanced_steps``) takes the
same grid over the long pole's variables, with Gruau's own ranges and the short pole at rest.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from evolution.ablation import StaticMapController
from evolution.config import NEATConfig
from evolution.phenotype import SigmoidSpec, SpikingSpec, as_spec, make_controller
from evolution.population import Genomes
from evolution.rollout import rollout
from evolution.task import Task
from tasks.cartpole import DEFAULT_PLANT, CartPoleParams, CartPoleTask, cartpole_failed
from tasks.double_pole import DoublePoleTask
from tasks.studies.cartpole import NONMARKOV, paper_spec

__all__ = ["GRID_FRACTIONS", "GRID_STEPS", "gruau_grid", "grid_ranges", "start_grid", "make_policy",
           "steps_from_starts", "policy_success_rate", "success_rate", "check_starts", "steps_balanced",
           "GRUAU_RANGES", "GENERALIZATION_STEPS", "generalization_starts", "balanced_steps"]

GRID_FRACTIONS = (0.05, 0.25, 0.5, 0.75, 0.95)  # [Gruau96]
GRID_STEPS = 1000  # [Gruau96]: balanced for 1000 steps counts as a success
_X_FRACTION = 0.9  # 2.16 m of a 2.4 m track
_THETA_FRACTION = 0.3  # 3.6 degrees of a 12-degree failure angle
_X_DOT_RANGE = 1.35  # m/s
_THETA_DOT_RANGE = math.radians(8.6)  # rad/s
_TAU_S = NONMARKOV["tau_s"]  # [Qiu19] Table II control period, 0.01 s


def gruau_grid(ranges: tuple[float, ...], fractions: tuple[float, ...] = GRID_FRACTIONS) -> Tensor:
    """Every combination of ``fractions`` of each range ``[-a, a]`` (the values ``a (2 f - 1)``),
    ``[len(fractions) ** len(ranges), len(ranges)]`` float64; the first variable varies slowest
    (``itertools.product`` order)."""
    frac = torch.tensor(fractions, dtype=torch.float64)
    return torch.cartesian_prod(*(a * (2.0 * frac - 1.0) for a in ranges))


def steps_balanced(task: Task, controller, starts: Tensor) -> Tensor:
    """Control steps ``[C, S]`` each of ``controller``'s ``C`` networks balances on ``task`` (up to its
    ``max_steps``) from each of the ``S`` start states ``starts`` (the task's state rows): one rollout
    of ``C x S`` episodes, row ``c * S + s`` running network ``c`` from start ``s``."""
    return rollout(task, controller, episodes=starts.shape[0], starts=starts).steps


def grid_ranges(plant: CartPoleParams = DEFAULT_PLANT) -> tuple[float, float, float, float]:
    """Half-ranges ``a`` of (x, x_dot, theta, theta_dot) for ``plant``, SI units."""
    return (_X_FRACTION * plant.x_limit, _X_DOT_RANGE, _THETA_FRACTION * plant.theta_limit, _THETA_DOT_RANGE)


def start_grid(plant: CartPoleParams = DEFAULT_PLANT, *, device: str | torch.device = "cpu",
               dtype: torch.dtype = torch.float32) -> Tensor:
    """The 625 start states ``[625, 4]``: every combination of the 5 fractions of each range.

    Row order: x varies slowest, theta_dot fastest (``itertools.product`` order).
    """
    return gruau_grid(grid_ranges(plant)).to(device=device, dtype=dtype)


def check_starts(starts: Tensor, plant: CartPoleParams = DEFAULT_PLANT, *, name: str = "starts") -> Tensor:
    """``starts`` as an ``[S, 4]`` tensor of finite states inside the failure limits, else ``ValueError``."""
    if not isinstance(starts, Tensor):
        starts = torch.as_tensor(starts, dtype=torch.float32)
    if starts.dim() == 1 and starts.shape[0] == 4:
        starts = starts.unsqueeze(0)
    if starts.dim() != 2 or starts.shape[-1] != 4 or starts.shape[0] == 0:
        raise ValueError(f"{name} must be a [S, 4] tensor of (x, x_dot, theta, theta_dot) with S >= 1, "
                         f"got shape {tuple(starts.shape)}")
    if not starts.is_floating_point():
        raise ValueError(f"{name} must be floating point, got {starts.dtype}")
    if not bool(torch.isfinite(starts).all()):
        raise ValueError(f"{name} holds NaN or inf")
    outside = cartpole_failed(starts, plant)
    if bool(outside.any()):
        raise ValueError(f"{name} rows {torch.nonzero(outside).flatten()[:10].tolist()} lie outside the failure "
                         f"limits (|x| <= {plant.x_limit}, |theta| <= {plant.theta_limit:.4f})")
    return starts


def make_policy(genomes: Genomes, config: NEATConfig, controller: str = "snn", *,
                spec: SpikingSpec | SigmoidSpec | None = None, plant: CartPoleParams = DEFAULT_PLANT,
                tau_s: float = _TAU_S, backend: str = "auto"):
    """The non-Markov controller (``"snn"`` or ``"sigmoid"``) of every genome, batched as ``R * P`` rows."""
    if controller not in ("snn", "sigmoid"):
        raise ValueError(f"controller must be 'snn' or 'sigmoid', got {controller!r}")
    spec = paper_spec("table2", controller) if spec is None else spec
    return make_controller(genomes, config, _task(plant, tau_s, 1), spec, backend=backend)


def _task(plant: CartPoleParams, tau_s: float, max_steps: int) -> CartPoleTask:
    return CartPoleTask.nonmarkov(plant=plant, tau_s=tau_s, max_steps=max_steps)


def steps_from_starts(policy, starts: Tensor, num_controllers: int | None = None, *, max_steps: int,
                      tau_s: float = _TAU_S, plant: CartPoleParams = DEFAULT_PLANT) -> Tensor:
    """Steps balanced ``[C, S]`` by each of the ``C`` controllers of ``policy`` from each of ``S``
    starts, as one rollout of ``C x S`` episodes."""
    starts = check_starts(starts, plant).to(device=policy.device, dtype=policy.dtype)
    return steps_balanced(_task(plant, tau_s, max_steps), policy, starts)


def policy_success_rate(policy, num_controllers: int | None = None, starts: Tensor | None = None, *,
                        steps: int = GRID_STEPS, tau_s: float = _TAU_S, plant: CartPoleParams = DEFAULT_PLANT) -> Tensor:
    """Fraction ``[C]`` (float64) of ``starts`` (default: the 625-state grid) that each of the
    ``C`` controllers in ``policy`` balances for ``steps`` control steps."""
    starts = start_grid(plant) if starts is None else starts
    balanced = steps_from_starts(policy, starts, max_steps=steps, tau_s=tau_s, plant=plant)
    return (balanced >= steps).to(torch.float64).mean(-1)


def success_rate(genomes: Genomes, config: NEATConfig, *, controller: str = "snn", starts: Tensor | None = None,
                 steps: int = GRID_STEPS, spec: SpikingSpec | SigmoidSpec | None = None,
                 plant: CartPoleParams = DEFAULT_PLANT, tau_s: float = _TAU_S) -> Tensor:
    """Fraction ``[R, P]`` (float64) of the start states each genome balances for ``steps`` steps.

    All ``R * P`` genomes x ``S`` starts (default the 625-state grid) run as one batch.
    """
    starts = start_grid(plant, device=genomes.device, dtype=genomes.weight.dtype) if starts is None else starts
    policy = make_policy(genomes, config, controller, spec=spec, plant=plant, tau_s=tau_s)
    rate = policy_success_rate(policy, starts=starts, steps=steps, tau_s=tau_s, plant=plant)
    return rate.view(genomes.num_runs, genomes.pop_size)


# --- the double pole: NEAT 2002's generalisation test -------------------------------------
# Gruau et al. (1996)'s test as NEAT 2002 runs it: the long pole's four variables each at 0.05,
# 0.25, 0.5, 0.75 and 0.95 of these ranges, the short pole at rest (625 starts).
GRUAU_RANGES = (2.16, 1.35, math.radians(3.6), math.radians(8.6))  # m, m/s, rad, rad/s
GENERALIZATION_STEPS = 1000  # steps balanced from a start to count it (NEAT 2002)


def generalization_starts(*, device: torch.device | str = "cpu") -> Tensor:
    """The 625 plant states ``[625, 6]`` (float64): x, x_dot, theta1, theta1_dot on the grid, theta2 = 0."""
    grid = gruau_grid(GRUAU_RANGES)
    starts = torch.zeros(grid.shape[0], 6, dtype=torch.float64)
    starts[:, :4] = grid
    return starts.to(device)


def balanced_steps(genomes: Genomes, config: NEATConfig, spec: SpikingSpec | SigmoidSpec | str | None = "snn", *,
                   velocities: bool = False,
                   starts: Tensor | None = None, max_steps: int = GENERALIZATION_STEPS,
                   task: DoublePoleTask | None = None, static_map_steps: int | None = None) -> Tensor:
    """Control steps ``[R, P, S]`` (int64) each genome balances on the double pole from each start
    (plant states ``[S, 6]``; default the standard start), up to ``max_steps``: one rollout of every
    genome x start. ``task``: the evolved task (its plant, start and observation bounds; default: DPV
    or DPNV's defaults by ``velocities``). ``static_map_steps``: run each controller as a memoryless
    map settled this many control steps per observation (``evolution.ablation.StaticMapController``)."""
    task = (DoublePoleTask(velocities=velocities, fitness="steps", max_steps=max_steps) if task is None
            else task.with_fitness("steps", max_steps))
    if starts is None:
        starts = task.reset(1, None, device=genomes.device)
    else:
        starts = task.starts(starts.to(device=genomes.device, dtype=torch.float64))
    # a name is its spec type's own defaults here (the study's), not the double pole's library defaults
    controller = make_controller(genomes, config, task, as_spec(spec))
    if static_map_steps is not None:
        controller = StaticMapController(controller, static_map_steps)
    return steps_balanced(task, controller, starts).view(genomes.num_runs, genomes.pop_size, -1)
