"""The task seam: a batched plant in plain torch that any controller of this toolkit can run on.

A task is what EvoTorch's ``Problem`` is to EvoTorch: write one and NEAT, weight search, Ray,
plots and checkpoints work on it. Subclass ``Task`` and give:

- ``observation_low`` / ``observation_high``: bounds of each observed variable (its own units);
  controllers code observations over them (``evolution.input_coding``: [0, 1] by default,
  values beyond saturate; or signed, about the middle of the range).
- ``action_size`` and ``action_max``: actions are ``[B, action_size]`` in
  ``[-action_max, action_max]`` (the controllers' decoders scale to it).
- ``max_steps``: the episode length (control steps); ``control_period_s``: the time one control
  step covers (s); spiking controllers run ``control_period_s / dt`` substeps per step.
- ``reset(batch, generator)``: start states ``[batch, ...]`` (a tensor, or a tuple of tensors
  with ``batch`` rows), drawn from ``generator`` where random.
- ``step(state, action)``: ``(next_state, reward [B], terminated [B] bool)``.
- ``observe(state)``: ``[B, observation_size]``.
- ``fitness``: ``"return"`` (sum of rewards) or ``"steps"`` (control steps survived).
- ``discrete_observations``: True where the observations are categories (one-hot codes, a grid
  cell) that jump from step to step rather than measurements of a continuous state; the
  defaults then read them one control step at a time (``evolution.defaults.default_spec``).

Everything is batched over rows: the rollout (``evolution.rollout``) runs every genome x every
episode as one batch and calls each method once per control step. Write the plant as tensor
operations over the leading batch axis; no Python loop over rows.

Bad output from a task (a wrong shape, NaN or inf) is caught at the seam and raised as
``TaskError`` naming the task, the method and field, and the (genome, episode) indices.

Optionally, ``native``: a ``NativeStep`` naming a C source that defines the same step and
observation natively (the ABI: ``snn_torch/kernels/csrc/native_plant.h``). With it, and a controller
with a C kernel, the rollout runs whole episodes in one native call (``evolution.kernels.episodes``);
the torch methods stay the definition (the native step is checked against them, bit for bit,
when it is bound) and the path on other devices, with no compiler, or when tracing.

The other side of the seam is a ``Controller``: what the rollout drives, row by row (a row is one
episode of one genome). ``evolution.phenotype`` has two (NEAT-SNN and sigmoid NEAT, picked by the
spec); any object with the protocol's members runs on every task too.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor

__all__ = ["Task", "TaskError", "FITNESS_KINDS", "NativeStep", "Controller"]

FITNESS_KINDS = ("return", "steps")
State = Tensor | tuple[Tensor, ...]


@runtime_checkable
class Controller(Protocol):
    """What the rollout needs of a controller of ``num_genomes`` networks (``G = R * P``).

    Rows are episodes: ``initial_state(network)`` takes ``network [B]`` (int64, the genome of each
    row) and returns the controller's per-row state (any tensor, or tuple of tensors, with the rows
    first); ``act(inputs, state)`` takes the coded observations ``[B, num_inputs]`` (in ``dtype``,
    coded as ``input_coding`` says) and returns ``(action [B, action_size], state, activity [B, ...])``
    (``activity``: what a trace records, e.g. spike counts); ``select(state, keep)`` the state of rows
    ``keep`` (int64 indices), when finished episodes are dropped. ``input_coding`` is ``(coding,
    clip)`` of ``evolution.input_coding`` (``("unit", True)``: [0, 1] over the task's bounds).
    """

    num_genomes: int

    @property
    def dtype(self) -> torch.dtype: ...

    @property
    def device(self) -> torch.device: ...

    @property
    def input_coding(self) -> tuple[str, bool]: ...

    def initial_state(self, network: Tensor) -> Any: ...

    def act(self, inputs: Tensor, state: Any) -> tuple[Tensor, Any, Tensor]: ...

    def select(self, state: Any, keep: Tensor) -> Any: ...


class TaskError(ValueError):
    """A task returned something malformed (shape, dtype, NaN or inf); the message says which
    task, method, field and batch indices."""


@dataclass(frozen=True)
class NativeStep:
    """A task's step and observation in C (``snn_torch/kernels/csrc/native_plant.h``).

    Attributes:
        source: the C file defining ``{prefix}_step_{f32,f64}`` and ``{prefix}_observe_{f32,f64}``
            for each dtype in ``dtypes`` (built once per machine by ``snn_torch.kernels.build``; it may
            ``#include "native_plant.h"`` and ``"portable_math.h"``).
        prefix: the functions' common prefix (a C identifier).
        state_width: columns of the task's ``[B, state_width]`` state tensor.
        params: the task's constants, handed to every call as ``const double *params``.
        dtypes: the state dtypes the source defines, ``"float32"`` and/or ``"float64"``.
    """

    source: Path
    prefix: str
    state_width: int
    params: tuple[float, ...] = ()
    dtypes: tuple[str, ...] = ("float32", "float64")

    def __post_init__(self) -> None:
        if not str(self.prefix).isidentifier():
            raise ValueError(f"NativeStep.prefix must be a C identifier, got {self.prefix!r}")
        if isinstance(self.state_width, bool) or not isinstance(self.state_width, int) or self.state_width < 1:
            raise ValueError(f"NativeStep.state_width must be a positive int, got {self.state_width!r}")
        if not self.dtypes or any(d not in ("float32", "float64") for d in self.dtypes):
            raise ValueError(f"NativeStep.dtypes must list 'float32' and/or 'float64', got {self.dtypes!r}")
        if not all(isinstance(p, (int, float)) and not isinstance(p, bool) and math.isfinite(p) for p in self.params):
            raise ValueError("NativeStep.params must be finite numbers")


class Task(ABC):
    """Base class of batched control tasks (see the module docstring for the contract)."""

    name: str = "task"
    observation_low: Sequence[float] = ()
    observation_high: Sequence[float] = ()
    action_size: int = 1
    action_max: float = 1.0
    max_steps: int = 1000
    control_period_s: float = 0.02
    fitness: str = "return"
    discrete_observations: bool = False  # categories that jump from step to step (module docstring)
    native: NativeStep | None = None  # the step in C, for whole episodes in one native call

    @property
    def observation_size(self) -> int:
        return len(self.observation_low)

    @abstractmethod
    def reset(self, batch: int, generator: torch.Generator, *, device: torch.device | str = "cpu",
              dtype: torch.dtype = torch.float32) -> State:
        """Start states of ``batch`` episodes."""

    @abstractmethod
    def step(self, state: State, action: Tensor) -> tuple[State, Tensor, Tensor]:
        """``(next_state, reward [B], terminated [B] bool)`` after one control step under ``action``."""

    @abstractmethod
    def observe(self, state: State) -> Tensor:
        """What the controller sees, ``[B, observation_size]``."""

    def validate(self) -> Task:
        """Check the declared fields once (``TaskError`` naming the field); returns ``self``."""
        low, high = list(self.observation_low), list(self.observation_high)
        if not low or len(low) != len(high):
            raise TaskError(f"task {self.name!r}: observation_low and observation_high must be non-empty and of "
                            f"equal length, got {len(low)} and {len(high)}")
        for k, (lo, hi) in enumerate(zip(low, high, strict=True)):
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise TaskError(f"task {self.name!r}: observation bounds [{lo}, {hi}] of variable {k} must be "
                                "finite with high > low")
        for field, value, ok in (
            ("action_size", self.action_size, isinstance(self.action_size, int) and self.action_size >= 1),
            ("action_max", self.action_max, isinstance(self.action_max, (int, float))
             and math.isfinite(self.action_max) and self.action_max > 0),
            ("max_steps", self.max_steps, isinstance(self.max_steps, int) and self.max_steps >= 1),
            ("control_period_s", self.control_period_s, isinstance(self.control_period_s, (int, float))
             and math.isfinite(self.control_period_s) and self.control_period_s > 0),
            ("fitness", self.fitness, self.fitness in FITNESS_KINDS),
        ):
            if not ok or isinstance(value, bool):
                raise TaskError(f"task {self.name!r}: {field} = {value!r} is not valid (action_size and max_steps: "
                                f"positive ints; action_max, control_period_s: positive; fitness: {FITNESS_KINDS})")
        if not isinstance(self.discrete_observations, bool):
            raise TaskError(f"task {self.name!r}: discrete_observations = {self.discrete_observations!r} must be "
                            "True or False")
        return self

    def bounds(self, *, device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32) -> tuple[Tensor, Tensor]:
        """``(low, high)`` observation bounds as ``[observation_size]`` tensors."""
        return (torch.tensor(list(self.observation_low), dtype=dtype, device=device),
                torch.tensor(list(self.observation_high), dtype=dtype, device=device))

    def __getstate__(self) -> dict:
        # the bound native plant (ctypes functions, evolution.kernels.native_plant) is rebuilt where unpickled
        return {k: v for k, v in self.__dict__.items() if k != "_native_plants"}

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(name={self.name!r}, observations={self.observation_size}, "
                f"actions={self.action_size}, max_steps={self.max_steps}, period={self.control_period_s} s)")
