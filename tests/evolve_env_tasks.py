"""Tiny tasks for ``snn-neat evolve module:Class`` (``tests/test_cli_evolve_env.py``): one that
learns in a few generations, and the faults the command must name in one line."""

from __future__ import annotations

import torch

from evolution.task import Task


class PointTask(Task):
    """Drive a point on [-1, 1] to 0: ``x += 0.2 a`` per step (clipped), reward ``-|x|``, 20 steps
    from a uniform start. Doing nothing scores about -10; steering to 0 about -1."""

    name = "point"
    observation_low = (-1.0,)
    observation_high = (1.0,)
    action_size = 1
    action_max = 1.0
    max_steps = 20
    control_period_s = 0.02
    reward_threshold = -3.5

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        x = torch.rand(batch, 1, generator=generator, dtype=torch.float64) * 2 - 1
        return x.to(device=device, dtype=dtype)

    def step(self, state, action):
        x = (state + 0.2 * action.to(state.dtype)).clamp(-1.0, 1.0)
        return x, -x[:, 0].abs(), torch.zeros(x.shape[0], dtype=torch.bool, device=x.device)

    def observe(self, state):
        return state


class NoThreshold(PointTask):
    """``PointTask`` without a threshold: every run spends its budget."""

    reward_threshold = None


class NotATask:
    """A class, but not an ``evolution.Task``."""


not_a_class = 3


class NeedsArgs(PointTask):
    """A task whose constructor wants an argument."""

    def __init__(self, size: int) -> None:
        self.size = size


class BadBounds(PointTask):
    """Fails ``Task.validate``: high below low."""

    observation_high = (-2.0,)


class BadThreshold(PointTask):
    """A threshold that is not a number."""

    reward_threshold = "high"
