"""Historical markings for new nodes: the node registry of a generation.

Splitting connection (i, j) creates a hidden node. Every genome of a run that splits the
same (i, j) in the same generation gets the same new node slot (as in Stanley &
Miikkulainen 2002), so the offspring stay comparable gene by gene. Slots come from the
run's free hidden slots: those no genome (nor species representative) of the run uses.
Slots whose node died out everywhere are free again, so the fixed index is reclaimed, not
exhausted; when a run has more distinct splits than free slots, the surplus splits (the
highest (i, j) in slot order) get no node and the caller skips them.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["assign_split_nodes"]


def assign_split_nodes(split_from: Tensor, split_to: Tensor, request: Tensor, used: Tensor,
                       first_hidden: int) -> tuple[Tensor, Tensor]:
    """New node slots for the requested splits, deduplicated per run.

    Args:
        split_from, split_to: ``[R, P]`` long, the connection (i, j) each genome splits.
        request: ``[R, P]`` bool, whether the genome splits at all.
        used: ``[R, N]`` bool, node slots in use anywhere in the run.
        first_hidden: index of the first hidden slot.

    Returns:
        ``(new_node [R, P] long, granted [R, P] bool)``: the slot for each request, and
        whether a free slot was available.
    """
    R, N = used.shape
    flat = split_from * N + split_to
    flat = torch.where(request, flat, torch.full_like(flat, N * N))  # sink for non-requests
    wanted = torch.zeros(R, N * N + 1, dtype=torch.bool, device=used.device)
    wanted.scatter_(1, flat, True)
    wanted = wanted[:, : N * N]
    rank = wanted.long().cumsum(1) - 1  # rank of each distinct (i, j) within its run
    slots = torch.arange(N, device=used.device)
    free = ~used & (slots >= first_hidden)
    # Free slots in ascending order first: sort key puts used slots after all free ones.
    order = torch.sort(torch.where(free, slots, slots + N), dim=1).indices
    n_free = free.sum(1, keepdim=True)
    k = torch.gather(rank, 1, flat.clamp_max(N * N - 1))
    granted = request & (k < n_free)
    new_node = torch.gather(order, 1, k.clamp(0, N - 1))
    return torch.where(granted, new_node, torch.zeros_like(new_node)), granted
