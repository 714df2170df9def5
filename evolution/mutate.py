"""Mutation operators over the whole ``[R, P]`` population, gated by Bernoulli masks.

Every function is pure: genomes in, new genomes out, random numbers from the per-run
``RunRNG``. ``active[R, P]`` marks the genomes that may mutate (elites are copied unchanged).
Decisions compare float64 uniforms with the configured probabilities. Every block of draws
covers every genome and slot, used or not, so a run's stream never depends on what happened
elsewhere; ``evolution.kernels.breed`` computes the same step, evaluating only the draws a
genome uses (a draw is addressed by its counter).
"""

from __future__ import annotations

from dataclasses import replace

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.innovation import assign_split_nodes
from evolution.population import Genomes, new_weights, reachability
from evolution.rng import RunRNG

__all__ = [
    "mutate_weights",
    "mutate_sigma",
    "mutate_toggle_enabled",
    "mutate_toggle_one",
    "recurrent_slots",
    "mutate_add_connection",
    "mutate_add_node",
    "add_connection_candidates",
]


def _bcast(mask: Tensor, like: Tensor) -> Tensor:
    return mask.view(*mask.shape, *([1] * (like.dim() - mask.dim())))


def mutate_weights(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor, severe: Tensor | None = None,
                   force: Tensor | None = None) -> Genomes:
    """[NEAT02]: with ``weight_mutate_rate`` a genome's weights mutate; then each gene is
    replaced by a fresh draw (``weight_replace_rate``) or perturbed by N(0, power^2).

    ``cfg.weight_mutate_per_gene`` ([NP]): every gene of an active genome decides alone:
    perturbed with ``weight_mutate_rate``, else replaced with ``weight_replace_rate``, else
    unchanged. Both draw the same random numbers, so neither shifts the other streams.

    ``cfg.weight_mutate_neatc`` ([NEATC] ``Genome::mutate_link_weights``, rate 1): the genomes
    that mutate their weights change every gene; ``severe[R, P]`` (drawn by the caller) marks
    the "severe" ones. The same counters: the normals' two uniforms are the step's size and the
    choice of the cold rate. ``force[R, P]``: those genomes mutate their weights whatever
    ``weight_mutate_rate`` (not in the per-gene rule).
    """
    P, N = g.pop_size, g.num_nodes
    genome_u = rng.rand(P, dtype=torch.float64)  # drawn in both modes, so the streams stay aligned
    u = rng.rand(P, N, N, dtype=torch.float64)
    genome_hit = genome_u < cfg.weight_mutate_rate
    if force is not None:
        genome_hit = genome_hit | force
    if cfg.weight_mutate_neatc:
        return _mutate_weights_neatc(g, cfg, active & genome_hit, u, rng.rand(P, N, N, 2, dtype=torch.float64),
                                     severe)
    noise, uniform = rng.randn_uniform(P, N, N, dtype=g.weight.dtype)
    if cfg.weight_mutate_per_gene:
        perturb = u < cfg.weight_mutate_rate
        replace = ~perturb & (u < cfg.weight_mutate_rate + cfg.weight_replace_rate)
        gene_hit = _bcast(active, g.weight) & (perturb | replace)
    else:
        replace = u < cfg.weight_replace_rate
        gene_hit = _bcast(active & genome_hit, g.weight)
    fresh = new_weights(cfg, noise, uniform)
    perturbed = g.weight + cfg.weight_mutate_power * noise
    new = torch.where(replace, fresh, perturbed.clamp(cfg.weight_min_value, cfg.weight_max_value))
    hit = gene_hit & g.conn
    # the genomes whose weights went through the rule (per gene: every active one)
    mutated = active if cfg.weight_mutate_per_gene else active & genome_hit
    return _weights_mutated(g, torch.where(hit, new, g.weight), mutated)


def _weights_mutated(g: Genomes, weight: Tensor, mutated: Tensor) -> Genomes:
    """``g`` with new weights; where ``mutated[R, P]``, ``mutation_num`` (when carried) records them
    ([NEATC] ``mutate_link_weights`` sets every gene's ``mutation_num`` to its weight)."""
    if g.mutation_num is None:
        return replace(g, weight=weight)
    return replace(g, weight=weight, mutation_num=torch.where(_bcast(mutated, weight), weight, g.mutation_num))


def _mutate_weights_neatc(g: Genomes, cfg: NEATConfig, hit: Tensor, choice: Tensor, pair: Tensor,
                          severe: Tensor | None) -> Genomes:
    """[NEATC]'s rule: gene k of a genome with n genes (slot order) draws ``choice``; it is
    perturbed above ``gauss``, replaced above ``cold``, else kept, by a step uniform in
    +-power: severe genomes 0.3 / 0.1; else the tail (n >= 10, k > 0.8 n) 0.5 / 0.3; else
    0 / -0.1 or 0 / 0 (half each)."""
    R, P = g.num_runs, g.pop_size
    sev = torch.zeros(R, P, dtype=torch.bool, device=g.device) if severe is None else severe
    flat = g.conn.flatten(2)
    count = flat.sum(-1, keepdim=True).to(torch.float64)
    index = (flat.cumsum(-1) - 1).to(torch.float64)
    tail = ((count >= 10.0) & (index > count * 0.8)).view_as(g.conn)
    sev = sev.view(R, P, 1, 1)
    gauss = torch.where(sev, 0.3, torch.where(tail, 0.5, 0.0))
    cold = torch.where(sev, 0.1, torch.where(tail, 0.3, torch.where(pair[..., 1] > 0.5, -0.1, 0.0)))
    step = ((2.0 * pair[..., 0] - 1.0) * cfg.weight_mutate_power).to(g.weight.dtype)
    new = torch.where(choice > gauss, g.weight + step, step).clamp(cfg.weight_min_value, cfg.weight_max_value)
    change = _bcast(hit, g.weight) & g.conn & (choice > cold)
    return _weights_mutated(g, torch.where(change, new, g.weight), hit)


def mutate_sigma(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """Perturb the decoder gain by N(0, sigma_mutate_power^2), kept in its bounds."""
    P = g.pop_size
    hit = active & (rng.rand(P, dtype=torch.float64) < cfg.sigma_mutate_rate)
    new = (g.sigma + cfg.sigma_mutate_power * rng.randn(P, dtype=g.sigma.dtype))
    new = new.clamp(cfg.sigma_min_value, cfg.sigma_max_value)
    return replace(g, sigma=torch.where(hit, new, g.sigma))


def mutate_toggle_enabled(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """Flip each gene's enabled flag with ``enabled_mutate_rate``."""
    P, N = g.pop_size, g.num_nodes
    flip = _bcast(active, g.conn) & g.conn & (rng.rand(P, N, N, dtype=torch.float64) < cfg.enabled_mutate_rate)
    return replace(g, enabled=g.enabled ^ flip)


def mutate_toggle_one(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor) -> Genomes:
    """[NEATC] ``mutate_toggle_enable(1)`` then ``mutate_gene_reenable``: with
    ``toggle_enable_prob`` one gene, the ``floor(u n)``-th of the ``n`` in slot order, is
    enabled if disabled, or disabled if another enabled gene leaves its source node; then with
    ``gene_reenable_prob`` the first disabled gene (slot order) is enabled. Draws three blocks
    of ``P`` (``breed_kernel`` takes them only when either probability is above 0)."""
    P, N = g.pop_size, g.num_nodes
    want = active & (rng.rand(P, dtype=torch.float64) < cfg.toggle_enable_prob)
    pick = rng.rand(P, dtype=torch.float64)
    again = active & (rng.rand(P, dtype=torch.float64) < cfg.gene_reenable_prob)
    flat = g.conn.flatten(2)
    n = flat.sum(-1)
    k = (pick * n.to(torch.float64)).long().clamp_max(n - 1).clamp_min(0)
    slot = torch.searchsorted(flat.long().cumsum(-1), (k + 1).unsqueeze(-1)).squeeze(-1).clamp_max(N * N - 1)
    enabled = g.enabled.flatten(2).clone()
    on = torch.gather(enabled, 2, slot.unsqueeze(-1)).squeeze(-1)
    row = (g.conn & g.enabled).sum(-1)  # [R, P, N]: enabled genes leaving each node
    others = torch.gather(row, 2, (slot // N).unsqueeze(-1)).squeeze(-1) - on.long()
    flip = want & (n > 0) & (~on | (others > 0))
    enabled.scatter_(2, slot.unsqueeze(-1), (on ^ flip).unsqueeze(-1))
    off = flat & ~enabled
    first = off.to(torch.int8).argmax(-1, keepdim=True)
    fix = (again & off.any(-1)).unsqueeze(-1)
    enabled.scatter_(2, first, torch.gather(enabled, 2, first) | fix)
    return replace(g, enabled=enabled.view_as(g.enabled))


def recurrent_slots(g: Genomes, cfg: NEATConfig) -> Tensor:
    """[NEATC]'s recurrent links, ``[R, P, N, N]``: (i, j) closes a cycle of enabled genes
    (i == j, or a path j -> i), or touches an output node."""
    N = g.num_nodes
    reach = reachability(g.conn & g.enabled)
    idx = torch.arange(N, device=g.device)
    output = (idx >= cfg.first_output) & (idx < cfg.first_hidden)
    fixed = (idx.unsqueeze(1) == idx) | output.unsqueeze(1) | output
    return reach.transpose(-1, -2) | fixed


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


def _flat(t: Tensor) -> Tensor:
    return t.flatten(0, 1)


def _pick_for(mask: Tensor, u: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """For a subset of genomes: a uniformly random True slot (i, j) of ``mask[K, N, N]``,
    the ``floor(u n)``-th of its ``n`` True slots in flat order, ``u[K]`` float64 uniforms.
    Returns ``(i, j, possible)``."""
    N = mask.shape[-1]
    flat = mask.flatten(1)
    n = flat.sum(1)
    k = (u * n.to(torch.float64)).long().clamp_max(n - 1).clamp_min(0)
    slot = torch.searchsorted(flat.long().cumsum(1), (k + 1).unsqueeze(1)).squeeze(1).clamp_max(N * N - 1)
    return slot // N, slot % N, n > 0


def _tries_law(u: Tensor, good: Tensor, total: Tensor, tries: int) -> tuple[Tensor, Tensor]:
    """[NEATC]'s random tries from one float64 uniform ``u[K]`` each: of ``tries`` draws, each good
    with ``good / total``, the first good one is the ``k``-th of the ``good`` (exactly uniformly),
    or none is: ``u`` below ``(1 - good / total)^tries``. Returns ``(k, possible)``; the fail
    chance is a product, as the kernel forms it (``breed.c``'s ``tries_law``, bit for bit)."""
    miss = 1.0 - good.double() / total.clamp_min(1).double()
    fail = torch.ones_like(u)
    for _ in range(tries):
        fail = fail * miss
    possible = (good > 0) & ~(u < fail)
    share = torch.where(possible, (u - fail) / torch.where(possible, 1.0 - fail, 1.0), 0.0)
    return (share * good.double()).long().clamp_max(good - 1).clamp_min(0), possible


def _pick_by_tries(mask: Tensor, node: Tensor, u: Tensor, loops: Tensor, tries: int, first_output: int
                   ) -> tuple[Tensor, Tensor, Tensor]:
    """[NEATC]'s ``mutate_add_link`` draw for a subset of genomes, from one uniform ``u[K]``: each of
    ``tries`` tries picks a pair (i any present node, j a present non-input node; where ``loops[K]``,
    the recurrent draw, half the tries a self-loop j -> j instead), and the first pair in
    ``mask[K, N, N]`` is taken. A slot's chance is then its share of the pairs (a self-loop
    ``1 + nodes`` shares in the recurrent draw, ``1`` otherwise) times ``1 - (1 - S)^tries``, S the
    chance of one try; ``u`` below ``(1 - S)^tries`` is a failure. The breeding kernel repeats
    these operations (``breed.c``). Returns ``(i, j, possible)``."""
    K, N = mask.shape[0], mask.shape[-1]
    nodes = node.sum(1)
    targets = node[:, first_output:].sum(1)
    loop_share = torch.where(loops, nodes, 0).view(K, 1, 1) * torch.eye(N, dtype=torch.long, device=mask.device)
    flat = (mask.long() * (1 + loop_share)).flatten(1)
    total = flat.sum(1)
    pairs = nodes * targets * torch.where(loops, 2, 1)
    target, possible = _tries_law(u, total, pairs, tries)
    slot = torch.searchsorted(flat.cumsum(1), (target + 1).unsqueeze(1)).squeeze(1).clamp_max(N * N - 1)
    return slot // N, slot % N, possible


def mutate_add_connection(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor, *,
                          return_wanted: bool = False, recurrent: Tensor | None = None,
                          prob: Tensor | None = None) -> Genomes | tuple[Genomes, Tensor]:
    """With ``conn_add_prob``, add one new enabled gene at a random candidate slot.

    Candidates are computed only for the genomes that mutate (random numbers are still
    drawn for all, so every run's stream is the same whatever happens elsewhere).
    ``return_wanted``: also return ``[R, P]`` bool, the genomes that drew the mutation
    (whether or not a slot was free; [NEATC]'s exclusive mutations go by it).
    ``recurrent[R, P]`` (with ``cfg.conn_add_recurrence``): those genomes take a recurrent
    slot (``recurrent_slots``), the others a non-recurrent one (without it: any free slot,
    as ``reproduce`` draws it); ``cfg.conn_add_tries``: the slot drawn as [NEATC] draws it
    (``_pick_by_tries``), else uniformly. ``prob[R, P]``: each genome's
    probability instead of ``conn_add_prob``.
    """
    P = g.pop_size
    want = active & (rng.rand(P, dtype=torch.float64) < (cfg.conn_add_prob if prob is None else prob))
    pick = rng.rand(P, dtype=torch.float64)
    init = new_weights(cfg, *rng.randn_uniform(P, dtype=g.weight.dtype))
    rows = torch.nonzero(_flat(want)).squeeze(1)
    if rows.numel() == 0:
        return (g, want) if return_wanted else g
    sub = Genomes(**{k: _flat(t)[rows].unsqueeze(0) for k, t in g.tensors().items()})
    cand = add_connection_candidates(sub, cfg)[0]
    loops = torch.zeros(rows.numel(), dtype=torch.bool, device=g.device)
    if cfg.conn_add_recurrence and recurrent is not None:
        rec = recurrent_slots(sub, cfg)[0]
        loops = _flat(recurrent)[rows]
        cand = cand & (rec == loops.view(-1, 1, 1))
    if cfg.conn_add_tries:
        src, dst, possible = _pick_by_tries(cand, sub.node[0], _flat(pick)[rows], loops, cfg.conn_add_tries,
                                            cfg.first_output)
    else:
        src, dst, possible = _pick_for(cand, _flat(pick)[rows])
    rows, src, dst = rows[possible], src[possible], dst[possible]
    values = _flat(init)[rows]
    first = None
    if cfg.conn_add_shared_weight or g.mutation_num is not None:
        first = _first_of_each_link(rows // P, loops[possible], src, dst, g.num_nodes)
    if cfg.conn_add_shared_weight:
        values = values[first]
    weight, conn, enabled = g.weight.clone(), g.conn.clone(), g.enabled.clone()
    _flat(weight)[rows, src, dst] = values
    _flat(conn)[rows, src, dst] = True
    _flat(enabled)[rows, src, dst] = True
    out = replace(g, weight=weight, conn=conn, enabled=enabled)
    if g.mutation_num is not None:  # [NEATC]: the generation's first such link records its weight, a later one 0
        mnum = g.mutation_num.clone()
        _flat(mnum)[rows, src, dst] = torch.where(first == torch.arange(rows.numel(), device=g.device), values, 0.0)
        out = replace(out, mutation_num=mnum)
    return (out, want) if return_wanted else out


def _first_of_each_link(run: Tensor, recurrent: Tensor, src: Tensor, dst: Tensor, N: int) -> Tensor:
    """For new links in child order, the position of the first one with the same run, slot and
    recurrent flag: [NEATC]'s innovation list gives a later one that first one's weight."""
    key = ((run * 2 + recurrent.long()) * N + src) * N + dst
    _, group = torch.unique(key, return_inverse=True)
    position = torch.arange(key.numel(), device=key.device)
    first = torch.full((int(group.max()) + 1 if key.numel() else 0,), key.numel(), device=key.device)
    return first.scatter_reduce(0, group, position, reduce="amin")[group]


# [NEATC] Genome::mutate_add_node draws 20 random genes (its walk over a small genome's genes, from
# the oldest, sits under ``if (false)`` in NEAT 1.2.1: dead code)
SPLIT_TRIES = 20


def _pick_split_neatc(conn: Tensor, enabled: Tensor, u: Tensor, first_bias: int, first_output: int
                      ) -> tuple[Tensor, Tensor, Tensor]:
    """[NEATC]'s choice of the gene to split, for a subset of genomes ``conn/enabled[K, N, N]``, from
    one uniform ``u[K]``: ``SPLIT_TRIES`` random genes are tried and the first enabled one not
    leaving a bias node (slots ``[first_bias, first_output)``) is taken: none with probability
    ``(1 - m / n)^20`` (u below it; m such genes of n), else the ``floor((u - fail) / (1 - fail) m)``-th
    of them in slot order. The breeding kernel repeats these operations (``breed.c``). Returns
    ``(i, j, possible)``."""
    N = conn.shape[-1]
    src_node = torch.arange(N, device=conn.device).view(1, N, 1)
    valid = (conn & enabled & ~((src_node >= first_bias) & (src_node < first_output))).flatten(1)
    n = conn.flatten(1).sum(1)
    m = valid.sum(1)
    pick, ok = _tries_law(u, m, n, SPLIT_TRIES)
    slot = torch.searchsorted(valid.long().cumsum(1), (pick + 1).unsqueeze(1)).squeeze(1).clamp_max(N * N - 1)
    return slot // N, slot % N, ok


def mutate_add_node(g: Genomes, cfg: NEATConfig, rng: RunRNG, active: Tensor,
                    reserved: Tensor | None = None, *, return_wanted: bool = False
                    ) -> tuple[Genomes, Tensor] | tuple[Genomes, Tensor, Tensor]:
    """With ``node_add_prob``, split a random enabled gene (i, j) into i -> k -> j (with
    ``cfg.node_add_neatc``, the gene [NEATC] picks: ``_pick_split_neatc``).

    The old gene is disabled; i -> k gets weight 1 and k -> j the old weight, so the
    network's function changes little. ``k`` comes from the run's node registry
    (``assign_split_nodes``); ``reserved[R, N]`` marks further slots in use (species
    representatives). Returns the genomes and ``[R, P]`` bool: splits refused for want
    of a free slot; with ``return_wanted``, also the genomes that drew the mutation.
    """
    R, P = g.num_runs, g.pop_size
    want = active & (rng.rand(P, dtype=torch.float64) < cfg.node_add_prob)
    pick = rng.rand(P, dtype=torch.float64)
    src = torch.zeros(R * P, dtype=torch.long, device=g.device)
    dst = torch.zeros_like(src)
    possible = torch.zeros(R * P, dtype=torch.bool, device=g.device)
    rows = torch.nonzero(_flat(want)).squeeze(1)
    if rows.numel() and cfg.node_add_neatc:
        src[rows], dst[rows], possible[rows] = _pick_split_neatc(_flat(g.conn)[rows], _flat(g.enabled)[rows],
                                                                 _flat(pick)[rows], cfg.num_inputs, cfg.first_output)
    elif rows.numel():
        src[rows], dst[rows], possible[rows] = _pick_for(_flat(g.enabled)[rows], _flat(pick)[rows])
    request = want & possible.view(R, P)
    used = g.node.any(1)
    if reserved is not None:
        used = used | reserved
    k, granted = assign_split_nodes(src.view(R, P), dst.view(R, P), request, used, cfg.first_hidden)
    rows = torch.nonzero(_flat(granted)).squeeze(1)
    weight, conn, enabled, node = g.weight.clone(), g.conn.clone(), g.enabled.clone(), g.node.clone()
    if rows.numel():
        i, j, kk = src[rows], dst[rows], _flat(k)[rows]
        w, c, e = _flat(weight), _flat(conn), _flat(enabled)
        old_w = w[rows, i, j]
        e[rows, i, j] = False
        w[rows, i, kk], c[rows, i, kk], e[rows, i, kk] = 1.0, True, True
        w[rows, kk, j], c[rows, kk, j], e[rows, kk, j] = old_w, True, True
        _flat(node)[rows, kk] = True
    out = replace(g, weight=weight, conn=conn, enabled=enabled, node=node)
    if g.mutation_num is not None and rows.numel():  # [NEATC]: a new node's genes record 0
        mnum = g.mutation_num.clone()
        _flat(mnum)[rows, i, kk] = 0.0
        _flat(mnum)[rows, kk, j] = 0.0
        out = replace(out, mutation_num=mnum)
    return (out, request & ~granted, want) if return_wanted else (out, request & ~granted)
