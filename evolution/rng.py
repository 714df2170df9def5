"""One counter-based random stream per evolutionary run.

A run's stream is a hash of its seed and a counter: draw ``m`` of the run is
``uniform(key, m) = mix64(key ^ mix64(m))`` (splitmix64's finaliser), so any draw can be
computed alone, in any order, on any device. A run's random numbers, and hence its whole
history, do not depend on which or how many other runs share its batch.

Each call to ``rand``/``randn`` takes the next block of counters: a block of shape
``[R, *shape]`` gives run ``r`` the counters ``offset[r] + arange(prod(shape))`` (``randn``
takes two counters per draw), and the offset advances by the block's size. Because a draw
is addressed by its counter, a fused kernel (``evolution.kernels.breed``) computes only the
draws it needs, the same numbers the tensor operators draw, without drawing the rest.

- float64 uniforms: 53 bits, ``[0, 1)``; float32 uniforms: the top 24 bits, ``[0, 1)``.
- normals: Box-Muller in float64, ``sqrt(-2 log(1 - u1)) cos(2 pi u2)`` with ``u1, u2`` the
  float64 uniforms at counters ``2k`` and ``2k + 1`` of the block, rounded to the dtype.
  ``log`` and ``cos`` are our own (``box_muller``: exact range reduction, then series to
  about 1e-16) and ``sqrt`` too (Newton), built from IEEE-exact operations only
  (``+ - * /``, exponent bits), so torch and the C kernels (``evolution/kernels/csrc/box_muller.h``) compute the
  same bits on any machine, and the C loops vectorise.

Arithmetic is on int64 tensors, which wrap like uint64 for ``+``, ``*`` and ``^``; right
shifts are made logical with a mask.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

# The C kernels' copy of these primitives: snn_torch/kernels/csrc/counter_rng.h.
from snn_torch.functional.counter_rng import bits, mix64, s64, srl, uniform01

__all__ = ["RunRNG", "mix64", "uniform01", "box_muller", "run_keys", "STREAM_GA"]

_s64 = s64
STREAM_GA = _s64(0x6E656174_67610001)  # "neatga": keeps the GA stream apart from other seeded streams
TWO_PI = 2.0 * math.pi
_srl, _bits = srl, bits


def _uniform01_f32(key: Tensor, counter: Tensor) -> Tensor:
    return _srl(_bits(key, counter), 40).to(torch.float32) * 2.0**-24


# Series coefficients: log1p(f) = 2s (1 + z/3 + z^2/5 + ...), s = f / (f + 2), z = s^2,
# |s| <= 0.1716; cos and sin on [0, pi/4]. Terms to below 2^-53 of the sum. The C kernels'
# copies (csrc/box_muller.h, hex floats) are checked equal by tests/evolution/test_kernel_sources.py.
_LOG_C = [1 / (2 * k + 1) for k in range(11)]
_COS_C = [(-1) ** k / math.factorial(2 * k) for k in range(10)]
_SIN_C = [(-1) ** k / math.factorial(2 * k + 1) for k in range(10)]
_LN2, _SQRT_HALF = 0.6931471805599453, 0.7071067811865476


def _horner(z: Tensor, coef: list[float]) -> Tensor:
    p = torch.full_like(z, coef[-1])
    for c in reversed(coef[:-1]):
        p = p * z + c
    return p


def _log_unit(x: Tensor) -> Tensor:
    """log(x) for float64 ``x`` in [2^-53, 1]."""
    m, e = torch.frexp(x)  # m in [0.5, 1)
    small = m < _SQRT_HALF
    m = torch.where(small, m * 2.0, m)
    e = torch.where(small, e - 1, e).to(torch.float64)
    f = m - 1.0
    s = f / (f + 2.0)
    return e * _LN2 + (s + s) * _horner(s * s, _LOG_C)


def _cos_2pi(u: Tensor) -> Tensor:
    """cos(2 pi u) for float64 ``u`` in [0, 1): reduced exactly to an angle in [0, pi/4]."""
    t = torch.where(u > 0.5, 1.0 - u, u)  # [0, 0.5]
    negate = t > 0.25
    t = torch.where(negate, 0.5 - t, t)  # [0, 0.25]
    use_sin = t > 0.125
    t = torch.where(use_sin, 0.25 - t, t)  # [0, 0.125]
    x = t * TWO_PI
    z = x * x
    v = torch.where(use_sin, x * _horner(z, _SIN_C), _horner(z, _COS_C))
    return torch.where(negate, -v, v)


def _sqrt(v: Tensor) -> Tensor:
    """sqrt(v) for float64 ``v`` in {0} or [2^-60, 2^60], to about 1 ulp. Ours, not
    ``torch.sqrt``: torch's float64 sqrt is not correctly rounded on every CPU (it differed
    from IEEE sqrt in 0.7 % of our draws), so it could not match C bit for bit."""
    m, e = torch.frexp(v)  # m in [0.5, 1)
    odd = (e & 1) == 1
    m = torch.where(odd, m * 2.0, m)  # [0.5, 2), e even
    half_e = torch.where(odd, e - 1, e) // 2
    y = 0.5 + 0.5 * m
    for _ in range(5):  # Newton: 6 % -> 2e-3 -> 2e-6 -> 1e-12 -> rounding
        y = 0.5 * (y + m / y)
    scale = ((half_e.to(torch.int64) + 1023) << 52).view(torch.float64)  # 2^(e/2), exact
    return torch.where(v == 0, 0.0, y * scale)


def box_muller(u1: Tensor, u2: Tensor) -> Tensor:
    """Standard normals from float64 uniforms in [0, 1): ``sqrt(-2 log(1 - u1)) cos(2 pi u2)``."""
    return _sqrt(-2.0 * _log_unit(1.0 - u1)) * _cos_2pi(u2)


def run_keys(seeds: list[int], device: torch.device | str = "cpu") -> Tensor:
    """Each run's stream key, ``[R]`` int64: ``mix64(mix64(seed) ^ STREAM_GA)``."""
    s = torch.tensor([_s64(x) for x in seeds], dtype=torch.int64, device=device)
    return mix64(mix64(s) ^ STREAM_GA)


class RunRNG:
    """Per-run counter streams on one device. Draws return tensors with a leading run axis.

    ``offsets`` (``[R]`` int64, on the CPU) is the whole state: the next counter of each run.
    """

    def __init__(self, seeds: list[int], device: torch.device | str = "cpu") -> None:
        if not seeds:
            raise ValueError("seeds must name at least one run")
        for s in seeds:
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < 2**63:
                raise ValueError(f"seeds must be non-negative integers below 2**63, got {s!r}")
        self.seeds = list(seeds)
        self.device = torch.device(device)
        self.keys = run_keys(self.seeds, self.device)
        self._offsets = torch.zeros(len(self.seeds), dtype=torch.int64)
        self._rows: Tensor | None = None  # a subset's rows of its parent's offsets

    def __len__(self) -> int:
        return len(self.seeds)

    @property
    def offsets(self) -> Tensor:
        """The next counter of each run, ``[R]`` int64 (a copy)."""
        return self._offsets.clone() if self._rows is None else self._offsets[self._rows]

    def take(self, count: int) -> Tensor:
        """Reserve ``count`` counters per run; returns each run's first one, ``[R]`` int64 (CPU)."""
        base = self.offsets
        if self._rows is None:
            self._offsets += count
        else:
            self._offsets[self._rows] += count
        return base

    def _counters(self, count: int, per_draw: int) -> Tensor:
        base = self.take(count * per_draw).to(self.device)
        return base.unsqueeze(1) + torch.arange(count * per_draw, device=self.device)

    def rand(self, *shape: int, dtype: torch.dtype = torch.float32) -> Tensor:
        """Uniform [0, 1) draws of shape ``[R, *shape]`` (float32 or float64)."""
        count = math.prod(shape)
        c = self._counters(count, 1)
        k = self.keys.unsqueeze(1)
        if dtype == torch.float64:
            out = uniform01(k, c)
        elif dtype == torch.float32:
            out = _uniform01_f32(k, c)
        else:
            raise ValueError(f"rand draws float32 or float64, not {dtype}")
        return out.view(len(self), *shape)

    def randn(self, *shape: int, dtype: torch.dtype = torch.float32) -> Tensor:
        """Standard normal draws of shape ``[R, *shape]``: ``box_muller`` in float64, rounded to ``dtype``."""
        return self.randn_uniform(*shape, dtype=dtype)[0]

    def randn_uniform(self, *shape: int, dtype: torch.dtype = torch.float32) -> tuple[Tensor, Tensor]:
        """``randn``'s draws and, from the same counters, each one's first uniform (float64, ``[R, *shape]``):
        the counters a draw takes do not depend on which of the two its caller uses."""
        count = math.prod(shape)
        c = self._counters(count, 2).view(len(self), count, 2)
        k = self.keys.view(-1, 1, 1)
        u = uniform01(k, c)
        normal = box_muller(u[..., 0], u[..., 1]).to(dtype).view(len(self), *shape)
        return normal, u[..., 0].reshape(len(self), *shape)

    def subset(self, runs: list[int]) -> RunRNG:
        """A view of some runs' streams (shared, not copied: draws advance them)."""
        sub = RunRNG.__new__(RunRNG)
        sub.seeds = [self.seeds[r] for r in runs]
        sub.device = self.device
        rows = torch.tensor(runs, dtype=torch.long)
        sub.keys = self.keys[rows.to(self.device)]
        sub._offsets = self._offsets
        sub._rows = rows if self._rows is None else self._rows[rows]
        return sub

    def get_state(self) -> Tensor:
        return self.offsets

    def set_state(self, state: Tensor) -> None:
        if not isinstance(state, Tensor) or state.dtype != torch.int64 or tuple(state.shape) != (len(self),):
            raise ValueError(f"expected the {len(self)} runs' stream offsets as an int64 tensor of shape "
                             f"[{len(self)}], got {state!r:.80}")
        if bool((state < 0).any()):
            raise ValueError("stream offsets must be non-negative")
        if self._rows is None:
            self._offsets.copy_(state.cpu())
        else:
            self._offsets[self._rows] = state.cpu()
