"""sin, cos, exp and the sigmoid with one definition in torch and in C, bit for bit.

torch's CPU ``sin``, ``cos`` and ``exp`` (SLEEF, vectorised) and the C library's (``libm``)
round differently in about 1 case in 100 to 1000, and CUDA's differ again. A plant or a
decoder that a C kernel runs as well as torch must not depend on which one ran it, so both
use these: the same float64 operations, in the same order, each rounded as IEEE 754 says (no
fused multiply-add; the C twin, ``snn_torch/kernels/csrc/portable_math.h``, is built with
``-ffp-contract=off``). Inputs of float32 are computed in float64 and rounded once at the end.

Accuracy (float64, tested against Python's ``math``, i.e. the C library): sin and cos are
correctly rounded in all but about 1 case in 10,000 and within 1 ulp always, for
``|x| <= 1e5`` rad (Cody-Waite reduction by pi/2 in three parts kept as a double-double, then
Taylor polynomials on ``[-pi/4, pi/4]`` whose leading terms are summed exactly with Dekker's
error-free products and Knuth's two-sum; beyond 1e5 rad the reduction loses bits); exp within
2 ulp on ``[-708, 708]``, with its argument clamped there (so ``exp`` never overflows:
``exp(1000)`` is ``exp(708)``); NaN in, NaN out. About 70 tensor ops for ``sin_cos``, 30 for
``exp``: the torch path of a plant pays that per step; the native paths pay a few ns.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["sin_cos", "exp", "sigmoid", "EXP_CLAMP"]

EXP_CLAMP = 708.0  # |argument| of exp: the result stays a normal, finite float64
_LOG2E = 1.4426950408889634
# ln 2 and pi/2 split so that k * high part is exact for the k that occur (fdlibm's splits)
_LN2_HI, _LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10
_TWO_OVER_PI = 6.36619772367581382433e-01
_PIO2_1, _PIO2_2, _PIO2_3 = 1.57079632673412561417e+00, 6.07710050630396597660e-11, 2.02226624871116645580e-21
# Taylor coefficients in Horner order: 1/n! (exp, n = 12 .. 2); the tails of sin and cos past
# their leading terms, (-1)^k/(2k+1)! for k = 8 .. 2 and (-1)^k/(2k)! for k = 9 .. 3
_EXP_C = tuple(1.0 / math.factorial(n) for n in range(12, 1, -1))
_SIN_TAIL = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(8, 1, -1))
_COS_TAIL = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(9, 2, -1))
# the leading coefficients -1/6 and 1/24 as double-doubles (high part, exact remainder)
_S1_HI, _S1_LO = -1.0 / 6.0, -9.25185853854297e-18
_C2_HI, _C2_LO = 1.0 / 24.0, 2.3129646346357427e-18
_SPLIT = 134217729.0  # 2^27 + 1: Dekker's splitting constant


def _horner(z: Tensor, coefficients: tuple[float, ...]) -> Tensor:
    """``c0 z^(m-1) + ... + c_(m-1)`` by Horner's rule, one rounding per op."""
    acc = torch.full_like(z, coefficients[0])
    for c in coefficients[1:]:
        acc = acc * z + c
    return acc


def _pow2(k: Tensor) -> Tensor:
    """``2**k`` (float64) for integer-valued float64 ``k`` in [-1022, 1023], from its bits."""
    return ((k.to(torch.int64) + 1023) << 52).view(torch.float64)


def _split(a: Tensor) -> tuple[Tensor, Tensor]:
    c = a * _SPLIT
    hi = c - (c - a)
    return hi, a - hi


def _two_prod(a: Tensor, b: Tensor) -> tuple[Tensor, Tensor]:
    """``(p, e)`` with ``p + e == a * b`` exactly (Dekker; no fused multiply-add needed)."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, (((ah * bh - p) + ah * bl) + al * bh) + al * bl


def _two_sum(a: Tensor, b: Tensor) -> tuple[Tensor, Tensor]:
    """``(s, e)`` with ``s + e == a + b`` exactly (Knuth)."""
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def sin_cos(x: Tensor) -> tuple[Tensor, Tensor]:
    """``(sin x, cos x)`` (x in rad), each in ``x``'s dtype; NaN for NaN or infinite ``x``."""
    x64 = x.to(torch.float64)
    finite = torch.isfinite(x64)
    x64 = torch.where(finite, x64, torch.zeros((), dtype=torch.float64, device=x.device))
    k = torch.floor(x64 * _TWO_OVER_PI + 0.5)  # nearest multiple of pi/2
    rh, rl = _two_sum(x64 - k * _PIO2_1, -(k * _PIO2_2))  # r = rh + rl in [-pi/4, pi/4]
    rl = rl - k * _PIO2_3
    zh, zl = _two_prod(rh, rh)
    # sin r = r - r^3/6 + r^5 (...): r - r^3/6 summed exactly, the tail and rl's share added after
    ch, cl = _two_prod(rh, zh)
    cl = cl + rh * zl
    th, tl = _two_prod(ch, torch.full_like(ch, _S1_HI))
    tl = (tl + ch * _S1_LO) + cl * _S1_HI
    s, e = _two_sum(rh, th)
    s = s + (e + ((tl + (ch * zh) * _horner(zh, _SIN_TAIL)) + rl * (1.0 - 0.5 * zh)))
    # cos r = 1 - r^2/2 + r^4/24 + r^6 (...): the same, with 1 - r^2/2 and r^4/24 exact
    w, e = _two_sum(torch.ones_like(zh), -(0.5 * zh))
    qh, ql = _two_prod(zh, zh)
    ql = ql + 2.0 * (zh * zl)
    uh, ul = _two_prod(qh, torch.full_like(qh, _C2_HI))
    ul = (ul + qh * _C2_LO) + ql * _C2_HI
    c, e2 = _two_sum(w, uh)
    c = c + (e2 + (e + (((ul - 0.5 * zl) + (qh * zh) * _horner(zh, _COS_TAIL)) - rl * rh)))
    q = k.to(torch.int64) & 3
    swap = (q & 1) == 1
    sin_r, cos_r = torch.where(swap, c, s), torch.where(swap, s, c)
    sin_x = torch.where(q >= 2, -sin_r, sin_r)
    cos_x = torch.where((q == 1) | (q == 2), -cos_r, cos_r)
    nan = torch.full((), math.nan, dtype=torch.float64, device=x.device)
    return torch.where(finite, sin_x, nan).to(x.dtype), torch.where(finite, cos_x, nan).to(x.dtype)


def _exp64(x64: Tensor) -> Tensor:
    xc = torch.clamp(x64, -EXP_CLAMP, EXP_CLAMP)  # NaN stays NaN
    k = torch.floor(xc * _LOG2E + 0.5)
    r = (xc - k * _LN2_HI) - k * _LN2_LO  # |r| <= 0.35
    p = 1.0 + r * (1.0 + r * _horner(r, _EXP_C))
    nan = torch.isnan(x64)
    return torch.where(nan, x64, p * _pow2(torch.where(nan, torch.zeros_like(k), k)))


def exp(x: Tensor) -> Tensor:
    """``e**x`` in ``x``'s dtype, the argument clamped to [-708, 708] (see the module docstring)."""
    return _exp64(x.to(torch.float64)).to(x.dtype)


def sigmoid(x: Tensor) -> Tensor:
    """``1 / (1 + exp(-x))`` in ``x``'s dtype (computed in float64, rounded once)."""
    return (1.0 / (1.0 + _exp64(-x.to(torch.float64)))).to(x.dtype)
