"""Compatibility distance of every genome to every species representative.

delta = c1 E / N + c2 D / N + c3 W + c4 |sigma_a - sigma_b|   ([NEAT02] plus [Qiu19]'s sigma term)

E, D: excess and disjoint genes; W: mean absolute weight difference of matching genes;
N: genes in the larger genome, or 1 when both have fewer than
``compatibility_normalize_min_genes`` ([NEAT02]). Slots carry no creation order, so a gene
is *excess* when its flat slot index ``i * N + j`` lies beyond the other genome's highest.
Counts come from one batched matmul; W loops over representatives (a fixed small number).
"""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.config import NEATConfig

__all__ = ["distance_matrix"]


def _highest_slot(conn_flat: Tensor) -> Tensor:
    G = conn_flat.shape[-1]
    idx = torch.arange(G, device=conn_flat.device)
    return torch.where(conn_flat, idx, -1).amax(-1)


def distance_matrix(
    conn: Tensor, weight: Tensor, sigma: Tensor,
    rep_conn: Tensor, rep_weight: Tensor, rep_sigma: Tensor, cfg: NEATConfig,
) -> Tensor:
    """Distances ``[R, P, S]`` from genomes ``[R, P, N, N]`` to representatives ``[R, S, N, N]``."""
    a = conn.flatten(2)
    b = rep_conn.flatten(2)
    wa = weight.flatten(2)
    wb = rep_weight.flatten(2)
    fa, fb = a.to(weight.dtype), b.to(weight.dtype)
    n_a = fa.sum(-1)  # [R, P]
    n_b = fb.sum(-1)  # [R, S]
    matching = fa @ fb.transpose(1, 2)  # [R, P, S]
    # Genes of a at or below b's highest slot (and vice versa), via prefix counts.
    top_a, top_b = _highest_slot(a), _highest_slot(b)
    cum_a = torch.cat([torch.zeros_like(fa[..., :1]), fa.cumsum(-1)], -1)  # [R, P, G + 1]
    cum_b = torch.cat([torch.zeros_like(fb[..., :1]), fb.cumsum(-1)], -1)
    S = b.shape[1]
    a_below_b = torch.gather(cum_a, 2, (top_b + 1).unsqueeze(1).expand(-1, a.shape[1], S))
    b_below_a = torch.gather(cum_b, 2, (top_a + 1).unsqueeze(1).expand(-1, S, a.shape[1])).transpose(1, 2)
    excess = (n_a.unsqueeze(-1) - a_below_b) + (n_b.unsqueeze(1) - b_below_a)
    disjoint = n_a.unsqueeze(-1) + n_b.unsqueeze(1) - 2 * matching - excess
    weight_diff = torch.stack(
        [((wa - wb[:, s : s + 1]).abs() * (a & b[:, s : s + 1])).sum(-1) for s in range(S)], -1)
    w_mean = torch.where(matching > 0, weight_diff / matching.clamp_min(1), torch.zeros_like(weight_diff))
    n_max = torch.maximum(n_a.unsqueeze(-1), n_b.unsqueeze(1))
    norm = torch.where(n_max >= cfg.compatibility_normalize_min_genes, n_max, torch.ones_like(n_max))
    return (cfg.compatibility_excess_coefficient * excess / norm
            + cfg.compatibility_disjoint_coefficient * disjoint / norm
            + cfg.compatibility_weight_coefficient * w_mean
            + cfg.compatibility_sigma_coefficient * (sigma.unsqueeze(-1) - rep_sigma.unsqueeze(1)).abs())
