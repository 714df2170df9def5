"""Crossover of aligned genomes: an element-wise choice between two parents.

Because slot (i, j) is the gene's historical marking, matching genes are ``conn_a & conn_b``
and disjoint or excess genes are ``conn_a ^ conn_b``; no alignment step is needed.
"""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.population import Genomes
from evolution.rng import RunRNG

__all__ = ["crossover"]


def crossover(fit: Genomes, other: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor,
              average: Tensor | None = None) -> Genomes:
    """Children of ``fit`` (the fitter parent) and ``other``, where ``active[R, P]``.

    [NEAT02]: matching genes take their weight from either parent at random; disjoint and
    excess genes come from the fitter parent (so do its nodes); a gene disabled in either
    parent is disabled in the child with probability ``disabled_inherit_prob``. The decoder
    gain ``sigma`` comes from either parent at random. Where ``active`` is False the child
    is ``fit`` unchanged. ``average[R, P]``: those children take the mean of the parents'
    weights for matching genes ([NEATC] ``Genome::mate_multipoint_avg``; the same draws).
    ``mutation_num``, where carried, is inherited as the weight is (averaged where it is).
    """
    P, N = fit.pop_size, fit.num_nodes
    matching = fit.conn & other.conn
    from_other = matching & (rng.rand(P, N, N, dtype=torch.float64) < 0.5)
    averaged = None if average is None else matching & average.view(*average.shape, 1, 1)

    def inherit(a: Tensor, b: Tensor) -> Tensor:  # a matching gene's value: either parent's, or their mean
        value = torch.where(from_other, b, a)
        return value if averaged is None else torch.where(averaged, (a + b) / 2, value)

    weight = inherit(fit.weight, other.weight)
    disabled_in_a_parent = fit.conn & (~fit.enabled | (matching & ~other.enabled))
    stays_disabled = disabled_in_a_parent & (rng.rand(P, N, N, dtype=torch.float64) < cfg.disabled_inherit_prob)
    enabled = fit.conn & ~stays_disabled
    sigma = torch.where(rng.rand(P, dtype=torch.float64) < 0.5, other.sigma, fit.sigma)
    mutation_num = None if fit.mutation_num is None else inherit(fit.mutation_num, other.mutation_num)
    child = Genomes(weight, fit.conn.clone(), enabled, fit.node.clone(), sigma, mutation_num)
    return fit.where(active, child)
