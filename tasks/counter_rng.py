"""Counter-based random numbers in torch, equal bit for bit to the closed-loop C kernels'.

The Markov task's Bernoulli input spikes come from a stream keyed by a hash of the genome
(FNV-1a over its weight bytes, then splitmix64), indexed by a counter that counts the draws
of an episode: draw ``k`` of substep ``q`` of control step ``t`` is counter
``(t * substeps + q) * n_inputs + k``. So a genome's episode does not depend on its batch,
its position, compaction or the thread count, and the torch reference path
(``MarkovSpikingPolicy.act``) draws exactly what the C kernel draws.

``mix64`` and ``uniform01`` are the GA streams' primitives (``evolution.rng``).
"""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.rng import _FNV_OFFSET, _FNV_PRIME, mix64, uniform01

__all__ = ["mix64", "uniform01", "fnv1a_keys"]


def fnv1a_keys(flat: Tensor) -> Tensor:
    """A key per row of ``flat`` ``[B, ...]``: FNV-1a over the row's bytes, then ``mix64``
    (``tasks.fused_loop.genome_keys`` computes the same in C)."""
    data = flat.contiguous().reshape(flat.shape[0], -1)
    raw = (data.view(torch.uint8) if data.dtype != torch.uint8 else data).to(torch.int64)
    h = torch.full((raw.shape[0],), _FNV_OFFSET, dtype=torch.int64, device=flat.device)
    for k in range(raw.shape[1]):
        h = (h ^ raw[:, k]) * _FNV_PRIME
    return mix64(h)
