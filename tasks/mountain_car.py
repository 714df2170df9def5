"""gymnasium's ``MountainCar-v0`` and ``MountainCarContinuous-v0`` as batched tasks of the seam,
with native steps (one C file, ``tasks/csrc/mountain_car.c``, for both).

A car in a valley, on the curve ``sin(3 x)``, too weak to climb out directly: it must swing back
and forth. Position x in [-1.2, 0.6] and velocity v in [-0.07, 0.07] in gymnasium's units (a
length without a unit, and that length per step; gymnasium's step has no time in seconds). Each
step: ``v += push - 0.0025 cos(3 x)``, clipped to +-0.07; ``x += v``, clipped to [-1.2, 0.6]; at
the left wall a negative velocity stops (v = 0). Episodes start at rest from x uniform in
[-0.6, -0.4).

``MountainCarTask`` (``MountainCar-v0``, gymnasium's ``MountainCarEnv``): the push is (action - 1)
0.001 for gymnasium's three actions, binned from the controller's output in [-1, 1]
(``tasks.gym_adapter.discrete_action``, ``GymTask``'s bins); the reward is -1 every step; the
episode terminates when ``x >= 0.5`` with ``v >= 0``; truncated at ``max_steps`` (200). All in
float64, as numpy computes it.

``MountainCarContinuousTask`` (``MountainCarContinuous-v0``, ``Continuous_MountainCarEnv``): the
push is ``0.0015 a`` for an action ``a`` clipped to [-1, 1]; the reward is ``-0.1 a^2`` per step
(the unclipped action, as gymnasium's) plus 100 on reaching ``x >= 0.45`` with ``v >= 0``, which
terminates the episode; truncated at ``max_steps`` (999). gymnasium keeps this environment's
state in float32 and its action is float32, so numpy computes most of the step in float32, except
its first step from a start state, which is float64; the port repeats both (see
``mountain_car_continuous_step``), so its state carries a third column: 1 until the first step.

Observations: (x, v) as gymnasium returns them (float32 values), bounded by gymnasium's
observation space. ``control_period_s`` (network time per control step, for spiking
controllers) defaults to 0.02 s: gymnasium's step has no duration. ``tests/tasks/
test_classic_control.py`` checks both against gymnasium's own environments.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor

from evolution.task import NativeStep, Task
from snn_torch.functional.portable_math import sin_cos
from snn_torch.functional.scalars import scalars
from tasks.gym_adapter import Bounds, discrete_action, port_options

__all__ = ["MountainCarTask", "MountainCarContinuousTask", "mountain_car_step", "mountain_car_continuous_step"]

_CSRC = Path(__file__).resolve().parent / "csrc"
MIN_POSITION, MAX_POSITION, MAX_SPEED = -1.2, 0.6, 0.07
FORCE, GRAVITY = 0.001, 0.0025  # MountainCar-v0's push per action step and gravity term
POWER = 0.0015  # MountainCarContinuous-v0's push per unit of action
GOAL, GOAL_CONTINUOUS = 0.5, 0.45
GOAL_REWARD, ACTION_COST = 100.0, 0.1  # MountainCarContinuous-v0's reward: 100 at the goal, -0.1 a^2 per step
PERIOD_S = 0.02  # s: gymnasium's step has no duration; a default network time per step
# gymnasium's observation space: float32 bounds
_F32 = torch.tensor([MIN_POSITION, MAX_POSITION, MAX_SPEED], dtype=torch.float32).tolist()
DEFAULT_BOUNDS = ((_F32[0], -_F32[2]), (_F32[1], _F32[2]))


def _start(batch: int, generator: torch.Generator) -> Tensor:
    """Positions uniform in [-0.6, -0.4) as numpy draws them (low + (high - low) U[0, 1)), float64."""
    return -0.6 + 0.2 * torch.rand(batch, generator=generator, dtype=torch.float64)


def mountain_car_step(state: Tensor, push: Tensor) -> tuple[Tensor, Tensor]:
    """``MountainCarEnv.step``: ``(next_state [B, 2], terminated [B])`` under ``push`` (``[B]``,
    (action - 1) 0.001), its operations in its order (float64 in numpy)."""
    position, velocity = state.unbind(-1)
    three, neg_gravity, speed, neg_speed, low, high, goal, zero = scalars(
        (3.0, -GRAVITY, MAX_SPEED, -MAX_SPEED, MIN_POSITION, MAX_POSITION, GOAL, 0.0), state)
    _, cos = sin_cos(three * position)
    velocity = torch.clamp(velocity + (push + cos * neg_gravity), neg_speed, speed)
    position = torch.clamp(position + velocity, low, high)
    velocity = torch.where((position == low) & (velocity < zero), zero, velocity)
    terminated = (position >= goal) & (velocity >= zero)
    return torch.stack([position, velocity], -1), terminated


def _continuous(position: Tensor, velocity: Tensor, a32: Tensor, a64: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``Continuous_MountainCarEnv.step`` on a state of one dtype W (float64: its first step from
    the float64 start; float32: every later step), numpy's types followed op by op: W op a Python
    float computes in W (the float rounded to W first, NEP 50), W op float32 in the wider of the two.
    ``a32``: the action (float32), ``a64``: it widened. ``(position, velocity, terminated)`` in W,
    before gymnasium stores them as float32."""
    f32, f64 = torch.float32, torch.float64
    one, power = scalars((1.0, POWER), a32)
    three, speed, neg_speed, low, high, goal, zero = scalars(
        (3.0, MAX_SPEED, -MAX_SPEED, MIN_POSITION, MAX_POSITION, GOAL_CONTINUOUS, 0.0), position)
    c_gravity, push_hi, push_lo = scalars((GRAVITY, POWER, -POWER), a64)
    # 0.0025 * math.cos(3 * position): the cosine of the W product, in double
    c = c_gravity * sin_cos((three * position).to(f64))[1]
    # min(max(a, -1.0), 1.0) keeps the float32 action within [-1, 1], and then its push (force *
    # power) and the push minus c are float32; beyond, the force is a Python float and both are double
    inside = (a32 >= -one) & (a32 <= one)
    inc_inside = (a32 * power - c.to(f32)).to(position.dtype)
    inc_beyond = (torch.where(a32 > one, push_hi, push_lo) - c).to(position.dtype)
    velocity = velocity + torch.where(inside, inc_inside, inc_beyond)
    velocity = torch.clamp(velocity, neg_speed, speed)
    position = torch.clamp(position + velocity, low, high)
    velocity = torch.where((position == low) & (velocity < zero), zero, velocity)
    return position, velocity, (position >= goal) & (velocity >= zero)


def mountain_car_continuous_step(state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``Continuous_MountainCarEnv.step``: ``(next_state [B, 3], reward [B] float64, terminated
    [B])`` under ``action`` (``[B]``, rounded to float32 as gymnasium's action is). Rows whose
    third column is nonzero take gymnasium's first step (in the state's dtype, float64 as numpy
    from its float64 start), the others its later ones (float32); the new state is stored as
    gymnasium stores it, in float32, with the third column 0."""
    a32 = action.to(torch.float32)
    a64 = a32.to(torch.float64)
    position, velocity, fresh = state.unbind(-1)
    position32, velocity32, terminated = _continuous(position.to(torch.float32), velocity.to(torch.float32), a32, a64)
    if state.dtype == torch.float32:  # both steps are float32 arithmetic: the same bits
        position, velocity = position32, velocity32
    else:
        position64, velocity64, terminated64 = _continuous(position, velocity, a32, a64)
        is_first = fresh != 0
        position = torch.where(is_first, position64, position32.to(state.dtype))
        velocity = torch.where(is_first, velocity64, velocity32.to(state.dtype))
        terminated = torch.where(is_first, terminated64, terminated)
    # reward = 100 on reaching the goal, minus math.pow(action, 2) * 0.1 (double, unclipped action)
    goal_reward, zero, cost = scalars((GOAL_REWARD, 0.0, ACTION_COST), a64)
    reward = torch.where(terminated, goal_reward, zero) - a64 * a64 * cost
    next_state = torch.stack([position.to(torch.float32).to(state.dtype), velocity.to(torch.float32).to(state.dtype),
                              torch.zeros_like(fresh)], -1)
    return next_state, reward, terminated


class MountainCarTask(Task):
    """``MountainCar-v0``: rock the car out of the valley with discrete pushes (module docstring).

    Args:
        observation_bounds: ``(low, high)`` of (x, v) replacing gymnasium's ([-1.2, 0.6],
            [-0.07, 0.07], as float32 values).
        max_steps: episode length (control steps; gymnasium's time limit: 200).
        control_period_s: network time per control step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default 0.02 s (gymnasium's step has no duration).
    """

    name = "MountainCar-v0"
    action_size = 1
    action_max = 1.0  # one output in [-1, 1], binned into gymnasium's three pushes
    discrete = 3  # gymnasium's Discrete(3), as GymTask's attribute
    fitness = "return"

    def __init__(self, *, observation_bounds: Bounds | None = None, max_steps: int = 200,
                 control_period_s: float = PERIOD_S) -> None:
        self.observation_low, self.observation_high, self.max_steps, self.control_period_s = port_options(
            type(self).__name__, observation_bounds, DEFAULT_BOUNDS, max_steps, control_period_s)
        # the same step in C (tasks/csrc/mountain_car.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "mountain_car.c", "mountain_car", 2, params=(
            FORCE, GRAVITY, MAX_SPEED, MIN_POSITION, MAX_POSITION, GOAL))
        self.validate()

    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        position = _start(batch, generator)
        return torch.stack([position, torch.zeros_like(position)], -1).to(device=device, dtype=dtype)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        one, force = scalars((1.0, FORCE), state)
        push = (discrete_action(action, 3).to(state.dtype) - one) * force  # (action - 1) * force
        moved, terminated = mountain_car_step(state, push)
        return moved, torch.full_like(state[:, 0], -1.0), terminated  # -1 every step

    def observe(self, state: Tensor) -> Tensor:
        return state.to(torch.float32).to(state.dtype)  # gymnasium's observation is float32


class MountainCarContinuousTask(Task):
    """``MountainCarContinuous-v0``: rock the car out of the valley with a continuous push,
    paying for effort (module docstring). State ``[B, 3]``: x, v and 1 until the first step.

    Args:
        observation_bounds: ``(low, high)`` of (x, v) replacing gymnasium's ([-1.2, 0.6],
            [-0.07, 0.07], as float32 values).
        max_steps: episode length (control steps; gymnasium's time limit: 999).
        control_period_s: network time per control step (s; spiking controllers run
            ``control_period_s / dt`` substeps); default 0.02 s (gymnasium's step has no duration).
    """

    name = "MountainCarContinuous-v0"
    action_size = 1
    action_max = 1.0  # gymnasium's Box(-1, 1)
    discrete = 0  # a Box action, as GymTask's attribute
    fitness = "return"

    def __init__(self, *, observation_bounds: Bounds | None = None, max_steps: int = 999,
                 control_period_s: float = PERIOD_S) -> None:
        self.observation_low, self.observation_high, self.max_steps, self.control_period_s = port_options(
            type(self).__name__, observation_bounds, DEFAULT_BOUNDS, max_steps, control_period_s)
        # the same step in C (tasks/csrc/mountain_car.c), for whole episodes in one native call
        self.native = NativeStep(_CSRC / "mountain_car.c", "mountain_car_continuous", 3, params=(
            POWER, GRAVITY, MAX_SPEED, MIN_POSITION, MAX_POSITION, GOAL_CONTINUOUS, GOAL_REWARD, ACTION_COST))
        self.validate()

    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        position = _start(batch, generator)
        state = torch.stack([position, torch.zeros_like(position), torch.ones_like(position)], -1)
        return state.to(device=device, dtype=dtype)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        moved, reward, terminated = mountain_car_continuous_step(state, action[:, 0])
        return moved, reward.to(state.dtype), terminated

    def observe(self, state: Tensor) -> Tensor:
        return state[:, :2].to(torch.float32).to(state.dtype)  # gymnasium's observation is float32
