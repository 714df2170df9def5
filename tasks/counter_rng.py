"""Counter-based random numbers in torch, equal bit for bit to the closed-loop C kernels'.

The Markov task's Bernoulli input spikes come from a stream keyed by a hash of the genome
(FNV-1a over its weight bytes, then splitmix64), indexed by a counter that counts the draws
of an episode: draw ``k`` of substep ``q`` of control step ``t`` is counter
``(t * substeps + q) * n_inputs + k``. So a genome's episode does not depend on its batch,
its position, compaction or the thread count, and the torch reference path
(``MarkovSpikingPolicy.act``) draws exactly what the C kernel draws.

Arithmetic is on int64 tensors, which wrap like uint64 for ``+``, ``*`` and ``^``; right
shifts are made logical with a mask.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["mix64", "uniform01", "fnv1a_keys"]


def _s64(c: int) -> int:
    """A uint64 constant as the int64 with the same bits."""
    return c - (1 << 64) if c >= 1 << 63 else c


_GOLDEN, _M1, _M2 = _s64(0x9E3779B97F4A7C15), _s64(0xBF58476D1CE4E5B9), _s64(0x94D049BB133111EB)
_FNV_OFFSET, _FNV_PRIME = _s64(0xCBF29CE484222325), 0x100000001B3


def _srl(x: Tensor, k: int) -> Tensor:
    """Logical right shift of int64 bits."""
    return (x >> k) & ((1 << (64 - k)) - 1)


def mix64(x: Tensor) -> Tensor:
    """splitmix64's finaliser (int64 in, int64 out), as ``mix64`` in the C kernels."""
    x = x + _GOLDEN
    x = (x ^ _srl(x, 30)) * _M1
    x = (x ^ _srl(x, 27)) * _M2
    return x ^ _srl(x, 31)


def uniform01(key: Tensor, counter: Tensor) -> Tensor:
    """Uniform float64 in [0, 1) from 53 bits of ``mix64(key ^ mix64(counter))`` (broadcast)."""
    return _srl(mix64(key ^ mix64(counter)), 11).to(torch.float64) * 2.0**-53


def fnv1a_keys(flat: Tensor) -> Tensor:
    """A key per row of ``flat`` ``[B, ...]``: FNV-1a over the row's bytes, then ``mix64``
    (``tasks.fused_loop.genome_keys`` computes the same in C)."""
    data = flat.contiguous().reshape(flat.shape[0], -1)
    raw = (data.view(torch.uint8) if data.dtype != torch.uint8 else data).to(torch.int64)
    h = torch.full((raw.shape[0],), _FNV_OFFSET, dtype=torch.int64, device=flat.device)
    for k in range(raw.shape[1]):
        h = (h ^ raw[:, k]) * _FNV_PRIME
    return mix64(h)
