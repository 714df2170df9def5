"""Double-pole balancing (Wieland 1991; Gruau, Whitley & Pyeatt 1996), batched, as a task of the seam.

Two poles of different lengths hinged side by side on one cart, both balanced at once by one
force. The field's standard memory benchmark in the form without velocities (DPNV), where the
controller sees only the cart position and the two angles.

Plant: the equations and constants of ESP (Gomez & Miikkulainen 1997) and NEAT (Stanley &
Miikkulainen 2002), integrated as they do: fourth-order Runge-Kutta with a 0.01 s step, two
steps per control step (0.02 s). State ``[B, 6]`` = (x (m), x_dot (m/s), theta1 (rad),
theta1_dot (rad/s), theta2 (rad), theta2_dot (rad/s)), float64. Failure: ``|x| > 2.4`` m or
either pole beyond 36 degrees.

``DoublePoleTask.with_velocities()`` (DPV, Markov): all six variables observed, fitness =
control steps balanced (NEAT 2002: up to 100,000). ``DoublePoleTask.without_velocities()``
(DPNV): x, theta1 and theta2 observed, fitness = Gruau et al.'s damping fitness over a 1000-step
episode, ``F = 0.1 t / 1000 + 0.9 * 0.75 / J`` with ``t`` the steps balanced and ``J`` the sum
over the last 100 balanced steps of ``|x| + |x_dot| + |theta1| + |theta1_dot|`` (the second
term only once ``t > 100``); it rewards keeping the cart and the long pole still, so a
controller cannot swing its way to a long balance. The task carries ``t`` and the last 100
terms in its state and pays ``F`` as the reward of the step the episode ends in (by failure or
at ``max_steps``), so the seam's return is exactly ``F``. ``fitness="damping-both-poles"`` adds
``|theta2| + |theta2_dot|`` to ``J`` (not Gruau's): it also pays for a short pole that rings, which
the long pole's terms do not see.
"""

from __future__ import annotations

import math
from dataclasses import astuple, dataclass
from pathlib import Path

import torch
from torch import Tensor

from evolution.task import NativeStep, Task
from snn_torch.functional.decode import ordered_sum
from snn_torch.functional.portable_math import sin_cos

__all__ = ["DoublePoleParams", "DEFAULT_DOUBLE_POLE", "double_pole_derivatives", "double_pole_step",
           "double_pole_failed", "DoublePoleTask", "DAMPING_WINDOW", "DAMPING_TERMS",
           "DAMPING_TOTAL_FLOOR"]

DAMPING_WINDOW = 100  # steps in Gruau's damping term
# the fitness names of DoublePoleTask, each with the plant variables its damping term sums
# (0: no damping term; 4: x, x_dot, theta1, theta1_dot, Gruau's; 6: the short pole's as well)
DAMPING_TERMS = {"steps": 0, "damping": 4, "damping-both-poles": 6}
# the least sum of |x| + |x_dot| + |theta1| + |theta1_dot| (m, m/s, rad, rad/s) over the window the
# damping term divides by (tasks/csrc/double_pole.c repeats it): a balancing controller's sum is
# around 1 to 10; only a plant at rest to within a micro-unit reaches it
DAMPING_TOTAL_FLOOR = 1e-6
_CSRC = Path(__file__).resolve().parent / "csrc"


@dataclass(frozen=True)
class DoublePoleParams:
    """Physical constants and failure limits (SI units), ESP's and NEAT 2002's values."""

    gravity: float = 9.8  # m/s^2
    cart_mass: float = 1.0  # kg
    pole1_mass: float = 0.1  # kg
    pole1_half_length: float = 0.5  # m
    pole2_mass: float = 0.01  # kg
    pole2_half_length: float = 0.05  # m
    pole_friction: float = 0.000002  # hinge friction coefficient (mu_p)
    tau_s: float = 0.01  # s, one Runge-Kutta step
    x_limit: float = 2.4  # m
    theta_limit: float = 0.628329  # rad, 36 degrees (ESP's constant)

    def __post_init__(self) -> None:
        for name in ("gravity", "cart_mass", "pole1_mass", "pole1_half_length", "pole2_mass", "pole2_half_length",
                     "tau_s", "x_limit", "theta_limit"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
                raise ValueError(f"DoublePoleParams.{name} must be a positive finite number, got {value!r}")
        if not (isinstance(self.pole_friction, (int, float)) and math.isfinite(self.pole_friction)
                and self.pole_friction >= 0):
            raise ValueError(f"DoublePoleParams.pole_friction must be >= 0, got {self.pole_friction!r}")


DEFAULT_DOUBLE_POLE = DoublePoleParams()


def double_pole_derivatives(state: Tensor, force: Tensor, p: DoublePoleParams = DEFAULT_DOUBLE_POLE) -> Tensor:
    """``d state / dt`` ``[B, 6]`` under ``force`` (N, ``[B]``): Wieland's equations as ESP writes them."""
    _, x_dot, th1, th1_dot, th2, th2_dot = state.unbind(-1)
    g = -p.gravity  # ESP's sign convention: gravity -9.8, angles positive the same way as x
    (sin1, cos1), (sin2, cos2) = sin_cos(th1), sin_cos(th2)  # portable_math: the C step's bits
    ml1, ml2 = p.pole1_half_length * p.pole1_mass, p.pole2_half_length * p.pole2_mass
    temp1, temp2 = p.pole_friction * th1_dot / ml1, p.pole_friction * th2_dot / ml2
    g_sin1, g_sin2 = g * sin1, g * sin2
    fi1 = ml1 * th1_dot * th1_dot * sin1 + 0.75 * p.pole1_mass * cos1 * (temp1 + g_sin1)
    fi2 = ml2 * th2_dot * th2_dot * sin2 + 0.75 * p.pole2_mass * cos2 * (temp2 + g_sin2)
    mi1 = p.pole1_mass * (1.0 - 0.75 * cos1 * cos1)
    mi2 = p.pole2_mass * (1.0 - 0.75 * cos2 * cos2)
    x_acc = (force + fi1 + fi2) / (mi1 + mi2 + p.cart_mass)
    th1_acc = -0.75 * (x_acc * cos1 + g_sin1 + temp1) / p.pole1_half_length
    th2_acc = -0.75 * (x_acc * cos2 + g_sin2 + temp2) / p.pole2_half_length
    return torch.stack([x_dot, x_acc, th1_dot, th1_acc, th2_dot, th2_acc], -1)


def double_pole_step(state: Tensor, force: Tensor, p: DoublePoleParams = DEFAULT_DOUBLE_POLE, *,
                     rk_steps: int = 2) -> Tensor:
    """``rk_steps`` fourth-order Runge-Kutta steps of ``p.tau_s`` under a constant ``force`` (N).

    ESP's ``rk4``: the derivative at the start, at two midpoints and at the end, weighted
    1, 2, 2, 1 over 6."""
    h, half = p.tau_s, 0.5 * p.tau_s
    for _ in range(rk_steps):
        k1 = double_pole_derivatives(state, force, p)
        k2 = double_pole_derivatives(state + half * k1, force, p)
        k3 = double_pole_derivatives(state + half * k2, force, p)
        k4 = double_pole_derivatives(state + h * k3, force, p)
        state = state + (h / 6.0) * (k1 + k4 + 2.0 * (k2 + k3))  # ESP's order: h6 * (dydx + dyt + 2 dym)
    return state


def double_pole_failed(state: Tensor, p: DoublePoleParams = DEFAULT_DOUBLE_POLE) -> Tensor:
    """True where the cart left the track or a pole fell past ``p.theta_limit``."""
    x, th1, th2 = state[..., 0], state[..., 2], state[..., 4]
    return (x.abs() > p.x_limit) | (th1.abs() > p.theta_limit) | (th2.abs() > p.theta_limit)


class DoublePoleTask(Task):
    """Double-pole balancing as a task: start with the long pole at ``theta1_0`` (rad, 0.07 as in
    ESP and NEAT 2002), everything else at rest; a force in ``[-10, 10]`` N every 0.02 s.

    Args:
        velocities: observe all six variables (DPV) or only x, theta1, theta2 (DPNV).
        fitness: ``"steps"`` (control steps balanced), ``"damping"`` (Gruau's fitness; the
            reward of the step the episode fails in, or of step ``max_steps``, is ``F``; every
            other step pays 0, so a rollout must run ``max_steps`` steps, the default) or
            ``"damping-both-poles"`` (the same, with the short pole's angle and angular velocity
            in the damping term as well).
        max_steps: episode length in control steps.
        plant: constants and limits; theta1_0: the long pole's start angle (rad).
        observation_bounds: symmetric bounds of each observed variable (m, m/s, rad, rad/s), in
            place of the defaults below; the seam normalises over them.

    Observation bounds (the seam normalises to [0, 1] over them, values beyond saturate): the
    failure limits for x and the angles; +-2 m/s and +-4 rad/s for the velocities (not given by
    the papers, which scale by 1/2; these cover what a balancing controller sees).
    """

    action_size = 1
    action_max = 10.0  # N
    X_DOT_BOUND, THETA_DOT_BOUND = 2.0, 4.0

    def __init__(self, *, velocities: bool, fitness: str = "steps", max_steps: int = 100_000,
                 plant: DoublePoleParams = DEFAULT_DOUBLE_POLE, theta1_0: float = 0.07, name: str | None = None,
                 observation_bounds: tuple[float, ...] | None = None) -> None:
        if fitness not in DAMPING_TERMS:
            raise ValueError(f"fitness must be one of {', '.join(map(repr, DAMPING_TERMS))}, got {fitness!r}")
        if not (isinstance(theta1_0, (int, float)) and abs(theta1_0) < plant.theta_limit):
            raise ValueError(f"theta1_0 must lie inside the failure angle {plant.theta_limit}, got {theta1_0!r}")
        self.velocities, self.damping, self.plant = bool(velocities), fitness != "steps", plant
        self.fitness_name = fitness  # the constructor's name (the seam's `fitness` below is "return" or "steps")
        self.damping_terms = DAMPING_TERMS[fitness]
        self.fitness = "return" if self.damping else "steps"
        self.theta1_0, self.max_steps = float(theta1_0), max_steps
        self.control_period_s = 2 * plant.tau_s
        self.name = name or ("double-pole-" + ("velocities" if velocities else "no-velocities"))
        self._columns = list(range(6)) if velocities else [0, 2, 4]
        lim_x, lim_th = plant.x_limit, plant.theta_limit
        bounds = ((lim_x, self.X_DOT_BOUND, lim_th, self.THETA_DOT_BOUND, lim_th, self.THETA_DOT_BOUND)
                  if velocities else (lim_x, lim_th, lim_th))
        if observation_bounds is not None:
            bounds = tuple(observation_bounds)
            if len(bounds) != len(self._columns) or not all(
                    isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) and b > 0
                    for b in bounds):
                raise ValueError(f"observation_bounds must be {len(self._columns)} positive finite "
                                 f"numbers (one per observed variable), got {observation_bounds!r}")
        self.observation_low = tuple(-b for b in bounds)
        self.observation_high = bounds
        self.native = NativeStep(_CSRC / "double_pole.c", "double_pole", 7 + DAMPING_WINDOW, dtypes=("float64",),
                                 params=(*astuple(plant), 2, self.damping_terms, max_steps, DAMPING_WINDOW,
                                         len(self._columns), *self._columns))
        self.validate()

    def with_fitness(self, fitness: str, max_steps: int) -> DoublePoleTask:
        """The same plant, start and observations with another fitness and episode length."""
        return DoublePoleTask(velocities=self.velocities, fitness=fitness, max_steps=max_steps, plant=self.plant,
                              theta1_0=self.theta1_0, observation_bounds=tuple(self.observation_high))

    @classmethod
    def with_velocities(cls, **kwargs) -> DoublePoleTask:
        """DPV: all six variables observed, fitness = steps balanced, 100,000 steps (NEAT 2002)."""
        return cls(**{"velocities": True, "fitness": "steps", "max_steps": 100_000, **kwargs})

    @classmethod
    def without_velocities(cls, **kwargs) -> DoublePoleTask:
        """DPNV: x, theta1, theta2 observed, Gruau's damping fitness over 1000 steps."""
        return cls(**{"velocities": False, "fitness": "damping", "max_steps": 1000, **kwargs})

    def reset(self, batch: int, generator: torch.Generator | None = None, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> Tensor:
        """``[batch, 6 + 1 + 100]`` float64: the plant, the steps balanced, the damping terms."""
        state = torch.zeros(batch, 7 + DAMPING_WINDOW, dtype=torch.float64, device=device)
        state[:, 2] = self.theta1_0
        return state

    def starts(self, plant_states: Tensor) -> Tensor:
        """Full task states from plant states ``[B, 6]`` (e.g. the 625 generalisation starts)."""
        state = torch.zeros(plant_states.shape[0], 7 + DAMPING_WINDOW, dtype=torch.float64,
                            device=plant_states.device)
        state[:, :6] = plant_states
        return state

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """One control step (the definition; ``tasks/csrc/double_pole.c`` repeats it natively, bit
        for bit, and the rollout uses that on the CPU)."""
        plant = double_pole_step(state[:, :6], action[:, 0].to(torch.float64), self.plant)
        failed = double_pole_failed(plant, self.plant)
        balanced = state[:, 6] + (~failed).to(torch.float64)
        new = torch.cat([plant, balanced.unsqueeze(1), state[:, 7:]], 1)
        if not self.damping:
            return new, (~failed).to(torch.float64), failed
        # the damping term of this step, in the slot of its step number (a ring over 100 steps)
        jiggle = ordered_sum(plant[:, :self.damping_terms].abs())
        slot = (state[:, 6].long() % DAMPING_WINDOW + 7).unsqueeze(1)
        ring = new.scatter(1, slot, torch.where(failed, new.gather(1, slot).squeeze(1), jiggle).unsqueeze(1))
        # paid once: at the failure, or on reaching max_steps (a longer rollout pays nothing more)
        ends = torch.where(failed, state[:, 6] < self.max_steps, balanced == self.max_steps)
        # slot order, as the native step; floored, so a plant held exactly at rest scores a finite
        # fitness (NEAT's code would divide by zero, and one infinite fitness turns the
        # offspring shares into NaN)
        total = ordered_sum(ring[:, 7:]).clamp_min(DAMPING_TOTAL_FLOOR)
        late = balanced > DAMPING_WINDOW
        fitness = 0.1 * (balanced / 1000.0) + torch.where(late, 0.9 * (0.75 / torch.where(late, total, 1.0)), 0.0)
        return ring, torch.where(ends, fitness, 0.0), failed

    def observe(self, state: Tensor) -> Tensor:
        return state[:, self._columns]
