"""Counter-based random numbers in torch: a draw is a pure function of a key and a counter.

``uniform01(key, m) = mix64(key ^ mix64(m))`` (splitmix64's finaliser), so any draw can be
computed alone, in any order, on any device, and a row's stream depends on nothing but its
key. ``evolution.rng`` builds the GA's per-run streams on these primitives; the Bernoulli
encoder keys its spikes by a hash of the genome (``fnv1a_keys``), so a genome's input spikes do
not depend on its batch, its position, compaction or the thread count.

Arithmetic is on int64 tensors, which wrap like uint64 for ``+``, ``*`` and ``^``; right shifts
are made logical with a mask.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

__all__ = ["mix64", "uniform01", "fnv1a_keys", "s64", "BernoulliSources"]


def s64(c: int) -> int:
    """A uint64 constant as the int64 with the same bits."""
    c &= (1 << 64) - 1
    return c - (1 << 64) if c >= 1 << 63 else c


_GOLDEN, _M1, _M2 = s64(0x9E3779B97F4A7C15), s64(0xBF58476D1CE4E5B9), s64(0x94D049BB133111EB)
FNV_OFFSET, FNV_PRIME = s64(0xCBF29CE484222325), 0x100000001B3


def srl(x: Tensor, k: int) -> Tensor:
    """Logical right shift of int64 bits."""
    return (x >> k) & ((1 << (64 - k)) - 1)


def mix64(x: Tensor) -> Tensor:
    """splitmix64's finaliser (int64 in, int64 out), as ``mix64`` in the C kernels."""
    x = x + _GOLDEN
    x = (x ^ srl(x, 30)) * _M1
    x = (x ^ srl(x, 27)) * _M2
    return x ^ srl(x, 31)


def bits(key: Tensor, counter: Tensor) -> Tensor:
    """64 random bits (as int64) of draw ``counter`` of stream ``key`` (broadcast)."""
    return mix64(key ^ mix64(counter))


def uniform01(key: Tensor, counter: Tensor) -> Tensor:
    """Uniform float64 in [0, 1) from 53 bits of ``mix64(key ^ mix64(counter))`` (broadcast)."""
    return srl(bits(key, counter), 11).to(torch.float64) * 2.0**-53


def fnv1a_keys(flat: Tensor) -> Tensor:
    """A 64-bit key (int64) per row of ``flat`` ``[B, ...]``: FNV-1a over the row's bytes, then
    ``mix64``. A pure function of the row's contents."""
    data = flat.contiguous().reshape(flat.shape[0], -1)
    raw = (data.view(torch.uint8) if data.dtype != torch.uint8 else data).to(torch.int64)
    h = torch.full((raw.shape[0],), FNV_OFFSET, dtype=torch.int64, device=flat.device)
    for k in range(raw.shape[1]):
        h = (h ^ raw[:, k]) * FNV_PRIME
    return mix64(h)


class BernoulliSources(NamedTuple):
    """Spike sources drawn from counter-based streams: source ``i`` of row ``r`` spikes in substep
    ``q`` when ``uniform01(keys[r], base + q * S + i) < prob[r, i]``.

    ``prob``: ``[B, S]`` float64 spike probability per substep; ``keys``: ``[B]`` int64 streams;
    ``base``: the first counter of this control step. The network kernel draws these in C (the
    same integer arithmetic, so the same spikes); ``spikes`` draws them in torch.
    """

    prob: Tensor
    keys: Tensor
    base: int

    def spikes(self, substeps: int, dtype: torch.dtype) -> Tensor:
        """``[B, substeps, S]`` spikes (0 or 1) in ``dtype``."""
        B, S = self.prob.shape
        counters = torch.arange(substeps * S, device=self.prob.device).view(1, substeps, S) + self.base
        u = uniform01(self.keys.view(B, 1, 1), counters)
        return (u < self.prob.unsqueeze(1)).to(dtype)
