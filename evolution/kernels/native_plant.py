"""A task's native step (``Task.native``), built, bound and checked against its torch step.

``native_plant(task, dtype)`` builds the task's C source once per machine (``snn_torch.kernels.build``:
the cache, the compiler flags, the fallback without a compiler), binds its step and observation
for one state dtype, and checks them against the torch methods before first use (once per task class, native
parameters and dtype in a process): 100 steps of 64 rows from the task's own start states
under actions across ``[-action_max, action_max]``,
state, reward, termination and observation compared bit for bit. A native step that disagrees
raises ``TaskError`` naming the task and what differed, instead of giving quietly different
results; one that returns NaN or inf is caught where it is used, as the torch step's would be.

A bound plant steps a torch batch (``step``, ``observe``: what the rollout's Python loop calls
on the CPU in place of the torch methods) and hands its function pointers to the episode loop
(``evolution.kernels.episodes``).
"""

from __future__ import annotations

import ctypes
import hashlib

import torch
from torch import Tensor

from evolution.task import NativeStep, Task, TaskError
from snn_torch.kernels.build import kernels_enabled, load_library

__all__ = ["NativePlant", "native_plant", "prototypes"]

_SUFFIX = {torch.float32: ("float32", "f32", "float"), torch.float64: ("float64", "f64", "double")}
CHECK_STEPS = 100  # steps of the check against the torch step, from each of the task's start states
CHECK_ROWS = 64
# (task class, NativeStep, dtype) already checked in this process: a task's step is a function of
# its class and its native params (the native source sees nothing else), so a second task object
# of the same kind (a champion test's copy of the fitness task) needs no second check
_CHECKED: set[tuple] = set()


def prototypes(native: NativeStep) -> str:
    """The C declarations of ``native``'s functions (``snn_torch/kernels/csrc/native_plant.h``), for ctypes."""
    lines = []
    for name, suffix, ctype in _SUFFIX.values():
        if name in native.dtypes:
            p = native.prefix
            lines.append(f"int {p}_step_{suffix}(const {ctype} *state, const double *action, {ctype} *next, "
                         f"double *reward, uint8_t *terminated, int64_t rows, const double *params);")
            lines.append(f"void {p}_observe_{suffix}(const {ctype} *state, double *observation, int64_t rows, "
                         f"const double *params);")
    return "\n".join(lines)


class NativePlant:
    """A task's native step and observation for one state dtype (see the module docstring)."""

    def __init__(self, task: Task, library, dtype: torch.dtype) -> None:
        native = task.native
        assert native is not None
        suffix = _SUFFIX[dtype][1]
        self.task, self.dtype, self.width = task, dtype, native.state_width
        self._step = getattr(library, f"{native.prefix}_step_{suffix}")
        self._observe = getattr(library, f"{native.prefix}_observe_{suffix}")
        self.step_ptr = ctypes.cast(self._step, ctypes.c_void_p).value
        self.observe_ptr = ctypes.cast(self._observe, ctypes.c_void_p).value
        self.params = torch.tensor([float(x) for x in native.params] or [0.0], dtype=torch.float64)

    def accepts(self, state) -> bool:
        """Whether ``state`` is what this plant steps: a CPU ``[B, width]`` tensor of its dtype."""
        return (isinstance(state, Tensor) and state.device.type == "cpu" and state.dtype == self.dtype
                and state.dim() == 2 and state.shape[1] == self.width)

    def step(self, state: Tensor, action: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """``task.step`` natively: ``(next_state, reward [B] (state dtype), terminated [B] bool)``."""
        state = state.contiguous()
        rows = state.shape[0]
        action = action.to(torch.float64).contiguous()
        out = torch.empty_like(state)
        reward = torch.empty(rows, dtype=torch.float64)
        terminated = torch.empty(rows, dtype=torch.bool)
        code = self._step(state.data_ptr(), action.data_ptr(), out.data_ptr(), reward.data_ptr(),
                          terminated.data_ptr(), rows, self.params.data_ptr())
        if code != 0:
            raise TaskError(f"task {self.task.name!r}: its native step returned error code {code}")
        return out, reward.to(self.dtype), terminated

    def observe(self, state: Tensor) -> Tensor:
        """``task.observe`` natively (``[B, observation_size]``, the state's dtype)."""
        state = state.contiguous()
        obs = torch.empty(state.shape[0], self.task.observation_size, dtype=torch.float64)
        self._observe(state.data_ptr(), obs.data_ptr(), state.shape[0], self.params.data_ptr())
        return obs.to(self.dtype)

    def check(self) -> NativePlant:
        """Compare with the torch step from the task's start states (``TaskError`` on a difference)."""
        task, name = self.task, self.task.name
        g = torch.Generator().manual_seed(0)
        state = task.reset(CHECK_ROWS, g, dtype=self.dtype)
        if not self.accepts(state):
            raise TaskError(f"task {name!r}: native step declared for [B, {self.width}] {self.dtype} states, but "
                            f"reset() gives {_describe(state)}")
        a_max = float(task.action_max)
        for t in range(CHECK_STEPS):
            # extremes, zero and uniform actions, so both signs and saturation are exercised
            u = torch.rand(state.shape[0], task.action_size, generator=g, dtype=torch.float64) * 2.0 - 1.0
            u[0], u[1], u[2] = 1.0, -1.0, 0.0
            action = (u * a_max).to(self.dtype)
            _same(name, "observation", t, self.observe(state), task.observe(state))
            ref_state, ref_reward, ref_term = task.step(state, action)
            new, reward, term = self.step(state, action)
            _same(name, "state", t, new, ref_state)
            _same(name, "reward", t, reward, ref_reward.to(self.dtype))
            _same(name, "terminated", t, term, ref_term)
            state = torch.where(ref_term.unsqueeze(1), task.reset(state.shape[0], g, dtype=self.dtype), ref_state)
        return self


def _describe(state) -> str:
    if isinstance(state, Tensor):
        return f"{tuple(state.shape)} {state.dtype} on {state.device}"
    return type(state).__name__


def _same(name: str, field: str, step: int, ours: Tensor, ref: Tensor) -> None:
    """``TaskError`` unless ``ours`` and ``ref`` hold the same values (NaN where the other has NaN)."""
    if not torch.equal(ours, ref) and not (ours.shape == ref.shape and ours.is_floating_point()
                                           and torch.equal(ours.isnan(), ref.isnan())
                                           and torch.equal(ours.nan_to_num(0.0), ref.nan_to_num(0.0))):
        raise TaskError(f"task {name!r}: its native step's {field} differs from the torch step's at check step "
                        f"{step} (the torch methods are the definition: the native source must repeat their "
                        f"operations in order, with sin/cos/exp from portable_math.h)")


def native_plant(task: Task, dtype: torch.dtype) -> NativePlant | None:
    """The task's bound, checked native plant for ``dtype`` states, or None (no ``task.native``,
    ``dtype`` not declared, no C compiler, or ``SNN_NEAT_C_KERNELS=0``). Bound once per task
    object and dtype."""
    native = task.native
    if native is None or dtype not in _SUFFIX or _SUFFIX[dtype][0] not in native.dtypes:
        return None
    if not kernels_enabled():
        return None
    bound = task.__dict__.setdefault("_native_plants", {})
    key = (native, dtype)
    if key not in bound:
        text = native.source.read_text()
        name = f"plant_{native.prefix}_{hashlib.sha256(text.encode()).hexdigest()[:10]}"
        library = load_library(name, native.source, prototypes(native))
        plant = None if library is None else NativePlant(task, library, dtype)
        checked = (type(task), native, dtype)
        if plant is not None and checked not in _CHECKED:
            plant.check()
            _CHECKED.add(checked)
        bound[key] = plant
    return bound[key]
