"""Compatibility distance of every genome to every species representative.

delta = c1 E / N + c2 D / N + c3 W + c4 |sigma_a - sigma_b|   ([NEAT02] plus [Qiu19]'s sigma term)

E, D: excess and disjoint genes; W: mean absolute weight difference of matching genes;
N: genes in the larger genome, or 1 when both have fewer than
``compatibility_normalize_min_genes`` ([NEAT02]). Slots carry no creation order, so a gene
is *excess* when its flat slot index ``i * N + j`` lies beyond the other genome's highest.

Everything reduces to batched matmuls and one L1 ``cdist``: matching counts are
``A @ B^T`` over 0/1 gene vectors, and the weight term uses
``sum_{A and B} |wa - wb| = L1(wa, wb) - sum_{A not B} |wa| - sum_{B not A} |wb|`` (weights
are exactly 0 where a genome has no gene). Per-genome statistics are computed once
(``gene_stats``) and reused against every set of representatives.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from evolution.config import NEATConfig

__all__ = ["GeneStats", "gene_stats", "distance", "distance_matrix"]


@dataclass
class GeneStats:
    """Per-genome gene vectors and summaries, ``[R, K, ...]``, in float64 whatever the
    weights' dtype, so the distances match the fused kernel's (which sums in double)."""

    has: Tensor  # [R, K, G] 1.0 where the gene exists
    w: Tensor  # [R, K, G] weight (0 where no gene)
    absw: Tensor  # [R, K, G]
    count: Tensor  # [R, K] genes
    abs_sum: Tensor  # [R, K] sum |w|
    top: Tensor  # [R, K] highest occupied flat slot (-1: none)
    upto: Tensor  # [R, K, G] genes at flat slots <= g
    sigma: Tensor  # [R, K]

    def select(self, runs: Tensor, index: Tensor) -> GeneStats:
        """Rows ``index[R', K']`` of runs ``runs[R']`` (copies only those rows)."""
        r = runs.unsqueeze(1)
        return GeneStats(**{name: getattr(self, name)[r, index] for name in self.__dataclass_fields__})

    def take(self, index: Tensor) -> GeneStats:
        """Rows ``index[R, K']`` of each run."""
        out = {}
        for name in self.__dataclass_fields__:
            t = getattr(self, name)
            idx = index.view(*index.shape, *([1] * (t.dim() - 2))).expand(*index.shape, *t.shape[2:])
            out[name] = torch.gather(t, 1, idx)
        return GeneStats(**out)


def gene_stats(conn: Tensor, weight: Tensor, sigma: Tensor) -> GeneStats:
    """Statistics of genomes ``conn/weight [R, K, N, N]``, ``sigma [R, K]``."""
    has = conn.flatten(2).to(torch.float64)
    w = torch.where(conn, weight, 0.0).flatten(2).to(torch.float64)
    absw = w.abs()
    G = has.shape[-1]
    top = torch.where(conn.flatten(2), torch.arange(G, device=has.device), -1).amax(-1)
    return GeneStats(has, w, absw, has.sum(-1), absw.sum(-1), top, has.cumsum(-1), sigma.to(torch.float64))


def _genes_upto(upto: Tensor, top: Tensor) -> Tensor:
    """Genes of each ``upto`` row at slots <= each ``top`` (0 for top = -1): ``[R, Ka, Kb]``."""
    Ka, Kb = upto.shape[1], top.shape[1]
    counts = torch.gather(upto, 2, top.clamp_min(0).unsqueeze(1).expand(-1, Ka, Kb))
    return torch.where(top.unsqueeze(1) >= 0, counts, 0.0)


def distance(a: GeneStats, b: GeneStats, cfg: NEATConfig) -> Tensor:
    """Distances ``[R, Ka, Kb]`` between every genome of ``a`` and every genome of ``b``."""
    bt = lambda t: t.transpose(1, 2)  # noqa: E731
    matching = a.has @ bt(b.has)
    a_upto_top_b = _genes_upto(a.upto, b.top)
    b_upto_top_a = bt(_genes_upto(b.upto, a.top))
    n_a, n_b = a.count.unsqueeze(-1), b.count.unsqueeze(1)
    excess = (n_a - a_upto_top_b) + (n_b - b_upto_top_a)
    disjoint = n_a + n_b - 2 * matching - excess
    l1 = torch.cdist(a.w, b.w, p=1)
    a_only = a.abs_sum.unsqueeze(-1) - a.absw @ bt(b.has)
    b_only = b.abs_sum.unsqueeze(1) - a.has @ bt(b.absw)
    weight_diff = (l1 - a_only - b_only).clamp_min(0.0)
    w_mean = torch.where(matching > 0, weight_diff / matching.clamp_min(1), 0.0)
    n_max = torch.maximum(n_a, n_b)
    norm = torch.where(n_max >= cfg.compatibility_normalize_min_genes, n_max, 1.0)
    return (cfg.compatibility_excess_coefficient * excess / norm
            + cfg.compatibility_disjoint_coefficient * disjoint / norm
            + cfg.compatibility_weight_coefficient * w_mean
            + cfg.compatibility_sigma_coefficient * (a.sigma.unsqueeze(-1) - b.sigma.unsqueeze(1)).abs())


def distance_matrix(conn: Tensor, weight: Tensor, sigma: Tensor, rep_conn: Tensor, rep_weight: Tensor,
                    rep_sigma: Tensor, cfg: NEATConfig) -> Tensor:
    """Distances ``[R, P, S]`` from genomes ``[R, P, N, N]`` to representatives ``[R, S, N, N]``."""
    return distance(gene_stats(conn, weight, sigma), gene_stats(rep_conn, rep_weight, rep_sigma), cfg)
