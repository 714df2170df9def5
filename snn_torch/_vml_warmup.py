"""Resolve MKL VML's kernel dispatch once, single-threaded, before any parallel use.

PyTorch's CPU wheels send contiguous float32/float64 unary ops (``log``, ``exp``, ``sin``,
``sqrt``, ...) to oneMKL's VML, one call per intra-op thread on its chunk. oneMKL 2024.2 (the
version torch 2.13.0 bundles) picks each VML function's kernel lazily on its first call, and
when that first call runs on several threads at once, one thread's chunk can be computed by
the low-accuracy kernel despite the high-accuracy mode torch asks for (pytorch/pytorch#188792,
errors up to thousands of ulp, on that one call only). We saw it here as a rare failure of a
test comparing against ``torch.log``: 24 % of 400,000 values off by up to 5e-13. A
one-element call of each function first, on one thread, settles the dispatch (the upstream
fix, pytorch/pytorch#188791, does the same). It costs well under a millisecond at import and
changes no correct result.
"""

from __future__ import annotations

import torch

__all__ = ["warm_up_vml", "WARMED_OPS"]

# A superset of the unary ops ATen routes to VML (the rest are harmless to call).
WARMED_OPS = ("abs", "acos", "asin", "atan", "ceil", "cos", "cosh", "erf", "erfc", "erfinv", "exp", "expm1",
              "floor", "lgamma", "log", "log10", "log1p", "log2", "reciprocal", "round", "rsqrt", "sigmoid", "sin",
              "sinh", "sqrt", "tan", "tanh", "trunc")
_done = False


def warm_up_vml() -> bool:
    """Call each of ``WARMED_OPS`` once on a one-element float32 and float64 tensor, once per
    process; True the first time."""
    global _done
    if _done:
        return False
    _done = True
    for dtype in (torch.float32, torch.float64):
        x = torch.full((1,), 0.5, dtype=dtype)
        for name in WARMED_OPS:
            getattr(torch, name)(x)
    return True
