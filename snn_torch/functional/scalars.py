"""Cached 0-dim tensors for the constants of per-step arithmetic.

An op between a tensor and a Python float converts the float on every call (about 3 us on
this CPU, more than the op itself on a small batch); the same op with a 0-dim tensor of the
tensor's dtype gives the same bits (the float is rounded to the dtype either way).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["scalar", "scalars"]

_CACHE: dict[tuple, Tensor] = {}


def scalar(value: float, like: Tensor) -> Tensor:
    """``value`` as a 0-dim tensor of ``like``'s dtype and device (cached; do not modify it)."""
    key = (float(value), like.dtype, like.device)
    t = _CACHE.get(key)
    if t is None:
        t = _CACHE[key] = torch.tensor(float(value), dtype=like.dtype, device=like.device)
    return t


_MANY: dict[tuple, tuple[Tensor, ...]] = {}


def scalars(values: tuple[float, ...], like: Tensor) -> tuple[Tensor, ...]:
    """``scalar(v, like)`` for each of ``values``, with one cache lookup for them all (a plant's or a
    decoder's constants, fetched once per step)."""
    key = (values, like.dtype, like.device)
    t = _MANY.get(key)
    if t is None:
        t = _MANY[key] = tuple(scalar(v, like) for v in values)
    return t
