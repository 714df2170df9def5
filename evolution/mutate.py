"""Mutation operators over the whole ``[R, P]`` population, gated by Bernoulli masks.

Every function is pure: genomes in, new genomes out, random numbers from the per-run
``RunRNG``. ``active[R, P]`` marks the genomes that may mutate (elites are copied unchanged).
"""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.innovation import assign_split_nodes
from evolution.population import Genomes, reachability
from evolution.rng import RunRNG

__all__ = [
    "mutate_weights",
    "mutate_sigma",
    "mutate_toggle_enabled",
    "mutate_add_connection",
    "mutate_add_node",
    "add_connection_candidates",
]


def _bcast(mask: Tensor, like: Tensor) -> Tensor:
    return mask.view(*mask.shape, *([1] * (like.dim() - mask.dim())))


def mutate_weights(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """[NEAT02]: with ``weight_mutate_rate`` a genome's weights mutate; then each gene is
    replaced by a fresh draw (``weight_replace_rate``) or perturbed by N(0, power^2)."""
    P, N = g.pop_size, g.num_nodes
    genome_hit = active & (rng.rand(P) < cfg.weight_mutate_rate)
    u = rng.rand(P, N, N)
    noise = rng.randn(P, N, N, dtype=g.weight.dtype)
    replace = u < cfg.weight_replace_rate
    fresh = cfg.weight_init_mean + cfg.weight_init_stdev * noise
    perturbed = g.weight + cfg.weight_mutate_power * noise
    new = torch.where(replace, fresh, perturbed).clamp(cfg.weight_min_value, cfg.weight_max_value)
    hit = _bcast(genome_hit, g.weight) & g.conn
    return Genomes(torch.where(hit, new, g.weight), g.conn, g.enabled, g.node, g.sigma)


def mutate_sigma(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """Perturb the decoder gain by N(0, sigma_mutate_power^2), kept in its bounds."""
    P = g.pop_size
    hit = active & (rng.rand(P) < cfg.sigma_mutate_rate)
    new = (g.sigma + cfg.sigma_mutate_power * rng.randn(P, dtype=g.sigma.dtype))
    new = new.clamp(cfg.sigma_min_value, cfg.sigma_max_value)
    return Genomes(g.weight, g.conn, g.enabled, g.node, torch.where(hit, new, g.sigma))


def mutate_toggle_enabled(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """Flip each gene's enabled flag with ``enabled_mutate_rate``."""
    P, N = g.pop_size, g.num_nodes
    flip = _bcast(active, g.conn) & g.conn & (rng.rand(P, N, N) < cfg.enabled_mutate_rate)
    return Genomes(g.weight, g.conn, g.enabled ^ flip, g.node, g.sigma)


def add_connection_candidates(g: Genomes, cfg: NEATConfig) -> Tensor:
    """Slots (i, j) where a new gene may go: both nodes present, no gene yet, j not an
    input or bias, and (feed-forward only) no cycle: i != j and no path j -> i."""
    present = g.node.unsqueeze(-1) & g.node.unsqueeze(-2)
    cand = present & ~g.conn
    cand[..., : cfg.first_output] = False
    if cfg.feed_forward:
        reach = reachability(g.conn)
        cand &= ~reach.transpose(-1, -2)
        cand &= ~torch.eye(g.num_nodes, dtype=torch.bool, device=g.device)
    return cand


def _pick_slot(mask: Tensor, rng: RunRNG) -> tuple[Tensor, Tensor, Tensor]:
    """One uniformly random True slot (i, j) per genome of ``mask[R, P, N, N]``."""
    R, P, N, _ = mask.shape
    scores = torch.where(mask, rng.rand(P, N, N), -1.0).flatten(2)
    flat = scores.argmax(-1)
    return flat // N, flat % N, mask.flatten(2).any(-1)


def mutate_add_connection(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """With ``conn_add_prob``, add one new enabled gene at a random candidate slot."""
    P = g.pop_size
    want = active & (rng.rand(P) < cfg.conn_add_prob)
    src, dst, possible = _pick_slot(add_connection_candidates(g, cfg), rng)
    init = cfg.weight_init_mean + cfg.weight_init_stdev * rng.randn(P, dtype=g.weight.dtype)
    init = init.clamp(cfg.weight_min_value, cfg.weight_max_value)
    do = want & possible
    idx = torch.arange(g.num_nodes, device=g.device)
    hit = ((idx == src.unsqueeze(-1)) & do.unsqueeze(-1)).unsqueeze(-1) & (idx == dst.unsqueeze(-1)).unsqueeze(-2)
    weight = torch.where(hit, _bcast(init, g.weight), g.weight)
    return Genomes(weight, g.conn | hit, g.enabled | hit, g.node, g.sigma)


def mutate_add_node(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor,
                    reserved: Tensor | None = None) -> tuple[Genomes, Tensor]:
    """With ``node_add_prob``, split a random enabled gene (i, j) into i -> k -> j.

    The old gene is disabled; i -> k gets weight 1 and k -> j the old weight, so the
    network's function changes little. ``k`` comes from the run's node registry
    (``assign_split_nodes``); ``reserved[R, N]`` marks further slots in use (species
    representatives). Returns the genomes and ``[R, P]`` bool: splits refused for want
    of a free slot.
    """
    P, N = g.pop_size, g.num_nodes
    want = active & (rng.rand(P) < cfg.node_add_prob)
    src, dst, possible = _pick_slot(g.enabled, rng)
    request = want & possible
    used = g.node.any(1)
    if reserved is not None:
        used = used | reserved
    k, granted = assign_split_nodes(src, dst, request, used, cfg.first_hidden)
    idx = torch.arange(N, device=g.device)
    # One-hot selectors for the touched slots.
    at_src = (idx == src.unsqueeze(-1)) & granted.unsqueeze(-1)  # [R, P, N]
    at_dst = idx == dst.unsqueeze(-1)
    at_k = idx == k.unsqueeze(-1)
    old_gene = at_src.unsqueeze(-1) & at_dst.unsqueeze(-2)  # (i, j)
    in_gene = at_src.unsqueeze(-1) & at_k.unsqueeze(-2)  # (i, k)
    out_gene = (at_k & granted.unsqueeze(-1)).unsqueeze(-1) & at_dst.unsqueeze(-2)  # (k, j)
    old_w = torch.gather(g.weight.flatten(2), 2, (src * N + dst).unsqueeze(-1)).squeeze(-1)
    weight = torch.where(in_gene, torch.ones((), dtype=g.weight.dtype, device=g.device), g.weight)
    weight = torch.where(out_gene, _bcast(old_w, weight), weight)
    new_genes = in_gene | out_gene
    enabled = (g.enabled & ~old_gene) | new_genes
    node = g.node | (at_k & granted.unsqueeze(-1))
    return Genomes(weight, g.conn | new_genes, enabled, node, g.sigma), request & ~granted
