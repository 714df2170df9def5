"""``recurrent_izhikevich_step`` compiled by ``torch.compile``, for the torch path on accelerators.

Eager torch runs one substep of ``P`` recurrent networks as the batched matmul and about 40
elementwise kernels (Heun's two stages, the crossing time, the reset and its second
integration), each reading and writing the whole ``[P, N]`` state. On a GPU at large ``P``
that memory traffic is the whole cost; ``torch.compile`` fuses the elementwise work into a
few kernels. On the CPU the C kernel (``snn_torch.kernels.network``) is faster
still, so compiling is opt-in there.

The compiled function is ``recurrent_izhikevich_substep`` itself (with spike counting), so the
reference and the compiled step cannot drift apart in what they compute; on the CPU they
agree bit for bit (tested). One compiled step serves every batch size (``dynamic=True``: no
recompilation when finished episodes are compacted away) and is shared by every caller with
the same neuron parameters, time step and method, so a new policy each generation compiles
nothing. If compiling fails (no C++ compiler, no Triton, an unsupported op), the step warns
once and runs eagerly: the same results, without the speed.
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Callable

import torch
from torch import Tensor

from snn_torch.functional.izhikevich import (
    DEFAULT_DT_MS,
    DEFAULT_METHOD,
    IzhikevichParams,
    check_dt,
    check_method,
)
from snn_torch.functional.recurrent import RecurrentState, recurrent_izhikevich_substep

__all__ = ["CompiledSubstep", "eager_substep"]

StepFn = Callable[..., tuple[Tensor, Tensor, Tensor, Tensor]]

_lock = threading.Lock()
# (params, dt_ms, method) -> the compiled step, one per process; or why compiling it failed
_compiled: dict[tuple, StepFn | str] = {}


def eager_substep(i_ext: Tensor, state: RecurrentState, w_eff: Tensor, counts: Tensor, p: IzhikevichParams, *,
                  dt_ms: float = DEFAULT_DT_MS, method: str = DEFAULT_METHOD,
                  source: Tensor | None = None) -> tuple[RecurrentState, Tensor]:
    """The uncompiled reference: one substep (``dt_ms``, ms) of ``P`` recurrent networks, its
    spikes added to ``counts`` (``recurrent_izhikevich_substep``). Returns ``(state, counts + z)``;
    inputs are not checked (they are inside a substep loop)."""
    return recurrent_izhikevich_substep(i_ext, state, w_eff, counts, p, dt_ms=dt_ms, method=method, source=source)


def _eager_step(p: IzhikevichParams, dt_ms: float, method: str) -> StepFn:
    """``eager_substep`` on plain tensors, the form that is compiled."""
    def step(i_ext: Tensor, v: Tensor, u: Tensor, z: Tensor, w_eff: Tensor, counts: Tensor,
             source: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        state, counts = eager_substep(i_ext, RecurrentState(v, u, z), w_eff, counts, p, dt_ms=dt_ms, method=method,
                                      source=source)
        return state.v, state.u, state.z, counts

    return step


def _compile(fn: StepFn) -> StepFn:
    """``torch.compile`` with one graph for every batch size (a separate function so that
    tests can make compilation fail)."""
    return torch.compile(fn, dynamic=True, fullgraph=True)


class CompiledSubstep:
    """One substep of ``P`` recurrent Izhikevich networks, compiled on first use.

    ``step(i_ext, state, w_eff, counts) -> (state, counts + z)``: ``i_ext`` (mV/ms) and the
    state ``[P, N]``, ``w_eff [P, N, N]`` as ``recurrent_izhikevich_step`` takes them (heaviside
    spikes, reset inside the step). ``dt_ms``: the substep (ms). ``compiled`` says whether the
    compiled function is in use (False once compiling has failed, or for tensor parameters,
    which are not compiled: their values would be baked into the graph).
    """

    def __init__(self, p: IzhikevichParams, *, dt_ms: float = DEFAULT_DT_MS, method: str = DEFAULT_METHOD) -> None:
        self.dt_ms = check_dt(dt_ms)
        check_method(method)
        self.eager = _eager_step(p, self.dt_ms, method)
        self.reason: str | None = None  # why the eager step is used, if it is
        if any(isinstance(x, Tensor) for x in p):
            self.reason = "tensor neuron parameters are not compiled"
            self._fn = self.eager
            return
        self._key = (tuple(float(x) for x in p), self.dt_ms, method)
        with _lock:
            if self._key not in _compiled:
                try:  # torch.compile compiles lazily, but refuses some setups (a Python it does not support) at once
                    _compiled[self._key] = _compile(_eager_step(IzhikevichParams(*self._key[0]), self.dt_ms, method))
                except Exception as exc:  # noqa: BLE001 - any refusal: the eager step is the same function
                    _compiled[self._key] = self._fail(exc)
                    self._fn = self.eager
                    return
            fn = _compiled[self._key]
        if isinstance(fn, str):  # failed before in this process, and said so then
            self.reason, self._fn = fn, self.eager
        else:
            self._fn = fn

    def _fail(self, exc: Exception) -> str:
        """Record and announce (once per process and key) why the eager step runs."""
        first_line = (str(exc).splitlines() or [""])[0][:200]
        self.reason = f"torch.compile failed ({type(exc).__name__}: {first_line})"
        warnings.warn(f"snn-neat: {self.reason}; running the substep eagerly", RuntimeWarning, stacklevel=3)
        return self.reason

    @property
    def compiled(self) -> bool:
        return self._fn is not self.eager

    def __call__(self, i_ext: Tensor, state: RecurrentState, w_eff: Tensor, counts: Tensor,
                 source: Tensor | None = None) -> tuple[RecurrentState, Tensor]:
        args = (i_ext, state.v, state.u, state.z, w_eff, counts, source)
        if self.compiled:
            try:
                v, u, z, counts = self._fn(*args)
                return RecurrentState(v, u, z), counts
            except Exception as exc:  # noqa: BLE001 - any compiler failure: the eager step is the same function
                # Bad input fails eagerly too, and raises here without turning compilation off.
                v, u, z, counts = self.eager(*args)
                with _lock:
                    _compiled[self._key] = self._fail(exc)
                self._fn = self.eager
                return RecurrentState(v, u, z), counts
        v, u, z, counts = self.eager(*args)
        return RecurrentState(v, u, z), counts
