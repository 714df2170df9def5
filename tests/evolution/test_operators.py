"""Genetic operators: invariants (property tests) and the rules of NEAT, gene by gene."""

import dataclasses

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from evolution.config import ConfigError
from evolution.crossover import crossover
from evolution.distance import distance_matrix
from evolution.innovation import assign_split_nodes
from evolution.kernels import breed as breed_kernel
from evolution.mutate import (
    add_connection_candidates,
    mutate_add_connection,
    mutate_add_node,
    mutate_sigma,
    mutate_toggle_enabled,
    mutate_toggle_one,
    mutate_weights,
)
from evolution.population import InvariantError, check_invariants, reachability
from evolution.reproduce import allocate_offspring, reproduce
from evolution.speciate import empty_species, speciate
from tests.evolution.helpers import (
    assert_same_breeding,
    bred_on_both_paths,
    genome_genes,
    population,
    reference_distance,
    small_config,
)

OPS = ["add_node", "add_conn", "weights", "sigma", "toggle", "toggle_one", "crossover", "generation"]
# NEAT C++ 1.2.1's options (evolution.neat121), all on
NEATC = dict(stagnant_fitness_factor=0.01, max_stagnation=2, species_elitism=0, obliterate_interval=2,
             obliterate_min_age=1, population_stagnation=2, mutation_exclusive=True, mate_only_prob=0.2,
             weight_mutate_neatc=True, crossover_average_prob=0.4, conn_add_recurrence=True, recur_only_prob=0.3,
             toggle_enable_prob=0.5, gene_reenable_prob=0.3)


def _apply(op, g, cfg, rng, state):
    R, P = g.num_runs, g.pop_size
    everyone = torch.ones(R, P, dtype=torch.bool)
    if op == "add_node":
        return mutate_add_node(g, cfg, rng, everyone, reserved=state.get("reserved"))[0]
    if op == "add_conn":
        return mutate_add_connection(g, cfg, rng, everyone)
    if op == "weights":
        return mutate_weights(g, cfg, rng, everyone)
    if op == "sigma":
        return mutate_sigma(g, cfg, rng, everyone)
    if op == "toggle":
        return mutate_toggle_enabled(g, cfg, rng, everyone)
    if op == "toggle_one":
        return mutate_toggle_one(g, cfg, rng, everyone)
    if op == "crossover":
        partner = g.gather(torch.roll(torch.arange(P), 1).expand(R, P).contiguous())
        return crossover(g, partner, cfg, rng, everyone)
    species, sp = state["species"], state["sp"]
    fitness = rng.rand(P, dtype=torch.float64) * 10
    children, _, sp, info = reproduce(g, fitness, species, sp, cfg, rng, state["gen"])
    species, sp = speciate(children, sp, cfg, rng, state["gen"] + 1)
    state.update(species=species, sp=sp, gen=state["gen"] + 1)
    return children


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), ops=st.lists(st.sampled_from(OPS), min_size=1, max_size=25),
       feed_forward=st.booleans(), self_loops=st.booleans(), node_add=st.sampled_from([0.3, 1.0]),
       neatc=st.booleans(), hidden=st.integers(0, 2))
def test_invariants_hold_after_every_operator(seed, ops, feed_forward, self_loops, node_add, neatc, hidden):
    cfg = small_config(feed_forward=feed_forward, initial_self_loops=self_loops and not feed_forward,
                       node_add_prob=node_add, conn_add_prob=0.5, enabled_mutate_rate=0.1, initial_hidden=hidden,
                       **(NEATC if neatc else {}))
    g, rng = population(cfg, seeds=(seed, seed + 1))
    species, sp = speciate(g, empty_species(2, cfg.num_nodes, 2, device=g.device, dtype=g.weight.dtype), cfg, rng, 0)
    state = {"species": species, "sp": sp, "gen": 0}
    check_invariants(g, cfg)
    for op in ops:
        g = _apply(op, g, cfg, rng, state)
        check_invariants(g, cfg)  # gene => both nodes; fixed nodes; enabled => exists; finite; size P
        assert g.pop_size == cfg.pop_size
        assert bool((state["species"] >= 0).all())


def test_a_start_with_hidden_nodes_wires_each_between_every_input_and_output():
    cfg = small_config(num_inputs=3, num_outputs=2, max_hidden=5, initial_hidden=2, feed_forward=True)
    g, _ = population(cfg)
    check_invariants(g, cfg)
    sources = range(cfg.first_output)  # 3 inputs and the bias
    outputs = range(cfg.first_output, cfg.first_hidden)
    hidden = range(cfg.first_hidden, cfg.first_hidden + 2)
    expected = ({(i, o) for i in sources for o in outputs} | {(i, h) for i in sources for h in hidden}
                | {(h, o) for h in hidden for o in outputs})
    for r in range(g.num_runs):
        for p in range(g.pop_size):
            assert set(genome_genes(g, r, p)) == expected
            assert all(enabled for _, enabled in genome_genes(g, r, p).values())
    assert g.num_hidden(cfg).eq(2).all()
    assert len(torch.unique(g.weight[..., 0, cfg.first_hidden])) == g.num_runs * g.pop_size  # weights drawn per gene
    # the start without hidden nodes is unchanged: the same weights on the genes both have
    plain, _ = population(dataclasses.replace(cfg, initial_hidden=0))
    assert plain.num_hidden(cfg).eq(0).all()
    assert torch.equal(plain.weight, torch.where(plain.conn, g.weight, 0.0))


@pytest.mark.parametrize("hidden", [-1, 6, 2.0, True])
def test_initial_hidden_must_fit_the_hidden_slots(hidden):
    with pytest.raises(ConfigError, match="initial_hidden"):
        small_config(max_hidden=5, initial_hidden=hidden)


@pytest.mark.skipif(not breed_kernel.kernel_available(), reason="no C compiler: kernels unavailable")
def test_kernels_breed_the_reference_generations_from_a_start_with_hidden_nodes():
    cfg = small_config(pop_size=40, max_hidden=6, initial_hidden=3, node_add_prob=0.3, conn_add_prob=0.3,
                       compatibility_threshold=1.0)
    g = torch.Generator().manual_seed(4)
    ref, fast = bred_on_both_paths(cfg, [2, 9], [(torch.rand(2, cfg.pop_size, generator=g, dtype=torch.float64),)
                                                 for _ in range(8)])
    assert_same_breeding(ref, fast)
    check_invariants(fast.genomes, cfg)
    assert int(fast.genomes.num_hidden(cfg).max()) > 3  # new nodes took the slots after the start's


def test_check_invariants_catches_each_violation():
    cfg = small_config()
    g, _ = population(cfg)
    check_invariants(g, cfg)
    bad = g.clone()
    bad.conn[0, 0, 0, 7] = True  # gene into a hidden node that does not exist
    with pytest.raises(InvariantError, match="missing node"):
        check_invariants(bad, cfg)
    bad = g.clone()
    bad.node[1, 2, cfg.first_output] = False
    with pytest.raises(InvariantError, match="output node is missing"):
        check_invariants(bad, cfg)
    bad = g.clone()
    bad.enabled[0, 1, 3, 0] = True
    with pytest.raises(InvariantError, match="enabled but does not exist"):
        check_invariants(bad, cfg)
    bad = g.clone()
    bad.weight[0, 0, 0, 3] = float("nan")
    with pytest.raises(InvariantError, match="NaN"):
        check_invariants(bad, cfg)


def test_add_node_splits_a_gene_and_dedups_the_new_node_per_run():
    cfg = small_config(pop_size=8, node_add_prob=1.0)
    g, rng = population(cfg, seeds=(3, 4))
    before = g.clone()
    after, refused = mutate_add_node(g, cfg, rng, torch.ones(2, 8, dtype=torch.bool))
    assert not refused.any()
    for r in range(2):
        new_by_split = {}
        for p in range(8):
            old, new = genome_genes(before, r, p), genome_genes(after, r, p)
            disabled = [k for k in old if old[k][1] and not new[k][1]]
            assert len(disabled) == 1
            (i, j) = disabled[0]
            k = [n for n in torch.nonzero(after.node[r, p]).flatten().tolist() if not before.node[r, p, n]]
            assert len(k) == 1 and k[0] >= cfg.first_hidden
            k = k[0]
            assert new[(i, k)] == (1.0, True)
            assert new[(k, j)] == (old[(i, j)][0], True)
            assert len(new) == len(old) + 2
            # Same split in the same generation -> same node slot; different splits differ.
            assert new_by_split.setdefault((i, j), k) == k
        assert len(set(new_by_split.values())) == len(new_by_split)


def test_node_slots_are_reclaimed_and_full_index_refuses_cleanly():
    used = torch.zeros(1, 6, dtype=torch.bool)
    used[0, :4] = True  # 4 fixed nodes, hidden slots 4 and 5 free
    src = torch.tensor([[0, 1, 0, 2]])
    dst = torch.tensor([[3, 3, 3, 3]])
    node, granted = assign_split_nodes(src, dst, torch.ones(1, 4, dtype=torch.bool), used, first_hidden=4)
    assert granted.tolist() == [[True, True, True, False]]  # three distinct splits, two free slots
    assert node[0, 0] == node[0, 2] == 4 and node[0, 1] == 5
    used[0, 4] = True  # slot 4 taken; slot 5 free again
    node, granted = assign_split_nodes(src, dst, torch.ones(1, 4, dtype=torch.bool), used, first_hidden=4)
    assert granted.tolist() == [[True, False, True, False]] and node[0, 0] == 5


def test_add_connection_never_duplicates_and_respects_feed_forward():
    for ff in (False, True):
        cfg = small_config(pop_size=20, conn_add_prob=1.0, node_add_prob=1.0, feed_forward=ff)
        g, rng = population(cfg)
        everyone = torch.ones(2, 20, dtype=torch.bool)
        for _ in range(6):
            g, _ = mutate_add_node(g, cfg, rng, everyone)
            n_before = g.conn.sum((-1, -2))
            cand = add_connection_candidates(g, cfg)
            g = mutate_add_connection(g, cfg, rng, everyone)
            check_invariants(g, cfg)
            assert torch.equal(g.conn.sum((-1, -2)), n_before + cand.flatten(2).any(-1).long())
        diag = torch.diagonal(reachability(g.conn), dim1=-2, dim2=-1).any()
        assert bool(diag) != ff  # recurrent genomes do grow cycles; feed-forward never


def test_crossover_follows_the_neat_rules():
    cfg = small_config(pop_size=400, node_add_prob=1.0, conn_add_prob=1.0, disabled_inherit_prob=0.75)
    g, rng = population(cfg, seeds=(7,))
    everyone = torch.ones(1, 400, dtype=torch.bool)
    a, _ = mutate_add_node(g, cfg, rng, everyone)
    a = mutate_add_connection(a, cfg, rng, everyone)
    b = mutate_weights(mutate_add_connection(g, cfg, rng, everyone), cfg, rng, everyone)
    b.enabled[..., 0, cfg.first_output] = False  # a gene disabled in parent b only
    child = crossover(a, b, cfg, rng, everyone)
    assert torch.equal(child.conn, a.conn) and torch.equal(child.node, a.node)  # genes of the fitter parent
    match = a.conn & b.conn
    from_a = match & (child.weight == a.weight)
    from_b = match & (child.weight == b.weight) & (a.weight != b.weight)
    frac_b = from_b.sum() / (match & (a.weight != b.weight)).sum()
    assert 0.4 < frac_b.item() < 0.6  # matching genes from either parent at random
    assert bool((from_a | from_b | ~match | (a.weight == b.weight)).all())
    only_a = a.conn & ~b.conn
    assert torch.equal(child.weight[only_a], a.weight[only_a])  # disjoint/excess from the fitter
    disabled_b = match & a.enabled & ~b.enabled
    frac_disabled = (~child.enabled[disabled_b]).float().mean().item()
    assert 0.65 < frac_disabled < 0.85  # disabled in a parent -> 75 % disabled
    untouched = crossover(a, b, cfg, rng, torch.zeros(1, 400, dtype=torch.bool))
    assert torch.equal(untouched.weight, a.weight)


def test_distance_matrix_equals_gene_list_reference():
    cfg = small_config(pop_size=12, node_add_prob=0.7, conn_add_prob=0.7, compatibility_normalize_min_genes=5,
                       compatibility_excess_coefficient=1.3, compatibility_disjoint_coefficient=0.7,
                       sigma_mutate_rate=1.0)
    g, rng = population(cfg, seeds=(11, 12))
    everyone = torch.ones(2, 12, dtype=torch.bool)
    for _ in range(4):
        g, _ = mutate_add_node(g, cfg, rng, everyone)
        g = mutate_sigma(mutate_weights(mutate_add_connection(g, cfg, rng, everyone), cfg, rng, everyone),
                         cfg, rng, everyone)
    reps = g.gather(torch.tensor([[0, 5, 9], [1, 2, 3]]))
    d = distance_matrix(g.conn, g.weight, g.sigma, reps.conn, reps.weight, reps.sigma, cfg)
    N = cfg.num_nodes
    for r in range(2):
        for p in range(12):
            for s in range(3):
                ref = reference_distance(genome_genes(g, r, p), genome_genes(reps, r, s), g.sigma[r, p].item(),
                                         reps.sigma[r, s].item(), cfg, N)
                assert d[r, p, s].item() == pytest.approx(ref, rel=1e-5, abs=1e-5)


def test_allocation_sums_to_pop_size_and_follows_mean_fitness():
    species = torch.tensor([[0, 0, 0, 1, 1, 2, 2, 2, 2, 2]])
    fitness = torch.tensor([[9.0, 9, 9, 3, 3, 1, 1, 1, 1, 1]], dtype=torch.float64)
    survivors = torch.tensor([[True, True, True]])
    counts = allocate_offspring(fitness, species, survivors, 10)
    assert counts.sum() == 10
    assert counts.tolist() == [[7, 2, 1]]  # shares 9 : 3 : 1 of 10 by largest remainder
    counts = allocate_offspring(fitness, species, torch.tensor([[False, True, True]]), 10)
    assert counts.tolist() == [[0, 8, 2]] and counts.sum() == 10
    flat = allocate_offspring(torch.ones(1, 10, dtype=torch.float64), species, survivors, 10)
    assert flat.sum() == 10 and flat.tolist() in ([[4, 3, 3]], [[3, 4, 3]], [[3, 3, 4]])


def test_per_gene_weight_mutation_follows_neat_python():
    """[NP]: every gene of an active genome is perturbed (rate), else replaced (replace
    rate), else kept; inactive genomes and absent genes never change."""
    cfg = small_config(pop_size=2000, weight_mutate_per_gene=True, weight_mutate_rate=0.6,
                       weight_replace_rate=0.3, weight_mutate_power=0.01, weight_init_stdev=5.0,
                       weight_max_value=1e6, weight_min_value=-1e6)
    g, rng = population(cfg, seeds=(21,))
    active = torch.ones(1, 2000, dtype=torch.bool)
    active[0, :500] = False
    after = mutate_weights(g, cfg, rng, active)
    assert torch.equal(after.weight[0, :500], g.weight[0, :500])
    assert torch.equal(after.weight[~g.conn], g.weight[~g.conn])
    genes = g.conn[0, 500:]
    delta = (after.weight[0, 500:] - g.weight[0, 500:]).abs()[genes]
    kept = (delta == 0).double().mean().item()
    small = ((delta > 0) & (delta < 0.05)).double().mean().item()  # perturbed by N(0, 0.01^2)
    large = (delta >= 0.05).double().mean().item()  # a fresh N(0, 5^2) draw
    assert kept == pytest.approx(0.1, abs=0.02)
    assert small == pytest.approx(0.6, abs=0.03)
    assert large == pytest.approx(0.3, abs=0.03)
    # Genome-level mutation (NEAT02) leaves a genome either untouched or changed everywhere.
    whole = mutate_weights(g, small_config(pop_size=2000, weight_mutate_rate=0.5), rng, active)
    changed = ((whole.weight != g.weight) & g.conn).flatten(2).any(-1)[0, 500:]
    all_changed = (((whole.weight != g.weight) | ~g.conn).flatten(2).all(-1))[0, 500:]
    assert torch.equal(changed, all_changed) and 0.4 < changed.double().mean().item() < 0.6


@pytest.mark.parametrize("elitism, min_size", [(1, 6), (2, 1), (3, 1)])
def test_elitism_copies_each_species_best_members_unchanged(elitism, min_size):
    cfg = small_config(pop_size=60, elitism=elitism, elitism_min_species_size=min_size, node_add_prob=0.5,
                       conn_add_prob=0.5)
    g, rng = population(cfg, seeds=(5, 6))
    everyone = torch.ones(2, 60, dtype=torch.bool)
    for _ in range(3):  # diverse genomes, so that a copy is recognisable
        g, _ = mutate_add_node(g, cfg, rng, everyone)
        g = mutate_weights(mutate_add_connection(g, cfg, rng, everyone), cfg, rng, everyone)
    species, sp = speciate(g, empty_species(2, cfg.num_nodes, 4, device=g.device, dtype=g.weight.dtype), cfg, rng, 0)
    fitness = torch.rand(2, 60, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    children, elite, _, info = reproduce(g, fitness, species, sp, cfg, rng, 1)
    for r in range(2):
        expected = 0
        for s in torch.unique(species[r]).tolist():
            members = torch.nonzero(species[r] == s).flatten()
            if info.offspring[r, s] == 0 or len(members) < min_size:
                continue
            best = members[torch.argsort(fitness[r, members], descending=True)][:min(elitism, len(members))]
            n = min(len(best), int(info.offspring[r, s]))
            expected += n
            for p in best[:n].tolist():  # each elite is an exact copy of its parent, flagged elite
                copies = [c for c in torch.nonzero(elite[r]).flatten().tolist()
                          if torch.equal(children.weight[r, c], g.weight[r, p])
                          and torch.equal(children.conn[r, c], g.conn[r, p])]
                assert copies, f"run {r}: member {p} of species {s} was not copied"
        assert int(elite[r].sum()) == expected
