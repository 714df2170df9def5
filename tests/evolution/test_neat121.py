"""NEAT C++ 1.2.1's GA mechanisms as NEATConfig options: each changes what it should (a test
that fails without it), and the C kernels give the tensor reference's result with it on."""

import dataclasses
import re
from pathlib import Path

import pytest
import torch

from evolution.checkpoint import CheckpointError
from evolution.config import ConfigError, NEATConfig
from evolution.crossover import crossover
from evolution.kernels import breed as breed_kernel
from evolution.kernels import select as select_kernel
from evolution.mutate import (
    add_connection_candidates,
    mutate_add_connection,
    mutate_add_node,
    mutate_toggle_enabled,
    mutate_toggle_one,
    mutate_weights,
    recurrent_slots,
)
from evolution.neat import NEAT
from evolution.neat121 import NEAT121_DPNV, NEAT121_DPV, neat121_config
from evolution.population import Genomes
from evolution.reporters import BaseReporter
from evolution.reproduce import _parents_per_species, reproduce, select_parents, species_offspring
from evolution.rng import RunRNG
from evolution.speciate import SpeciesState, empty_species, speciate
from tests.evolution.helpers import assert_same_breeding, bred_on_both_paths, population, small_config

needs_kernel = pytest.mark.skipif(not breed_kernel.kernel_available(), reason="no C compiler: kernels unavailable")


def _state(R: int, S: int) -> SpeciesState:
    return empty_species(R, 2, S, device=torch.device("cpu"), dtype=torch.float32)


def _both(fitness, species, sp, cfg, generation):
    """species_offspring by the tensor reference, and by the C kernel where it runs (equal)."""
    ref = species_offspring(fitness, species, sp, cfg, generation)
    if select_kernel.kernel_available():
        fast = select_kernel.species_state_offspring(fitness, species, sp, cfg, generation)
        for name, t in ref[0].tensors().items():
            assert torch.equal(t, getattr(fast[0], name)), name
        assert torch.equal(ref[1], fast[1]) and torch.equal(ref[2], fast[2]) and torch.equal(ref[3], fast[3])
    return ref


def _three_species(pop=30):
    # Species 0 and 1 improve now; species 2 (the worst) last improved 20 generations ago.
    species = torch.tensor([[0] * 10 + [1] * 10 + [2] * (pop - 20)])
    fitness = torch.tensor([[3.0] * 10 + [2.0] * 10 + [1.0] * (pop - 20)], dtype=torch.float64)
    sp = _state(1, 3)
    sp.alive[:] = True
    sp.best_fitness[:] = torch.tensor([[1.0, 1.0, 5.0]], dtype=torch.float64)
    sp.last_improved[:] = torch.tensor([[0, 0, -20]])
    return fitness, species, sp, small_config(pop_size=pop, species_elitism=0, max_stagnation=15)


# --- 1. stagnant species penalised, not removed ------------------------------------------
def test_a_stagnant_species_survives_with_its_share_cut_to_one_percent():
    fitness, species, sp, cfg = _three_species()
    _, survivors, counts, _ = _both(fitness, species, sp, cfg, 5)
    assert survivors.tolist() == [[True, True, False]] and counts[0, 2] == 0  # removed ([NEAT02])
    cfg = dataclasses.replace(cfg, stagnant_fitness_factor=0.01)
    _, survivors, counts, _ = _both(fitness, species, sp, cfg, 5)
    assert survivors.tolist() == [[True, True, True]]
    # shares 3 : 2 : 0.01 of 30 offspring: the stagnant species keeps a chance, no offspring here
    assert counts.tolist() == [[18, 12, 0]]
    cfg = dataclasses.replace(cfg, stagnant_fitness_factor=0.5)
    assert _both(fitness, species, sp, cfg, 5)[2].tolist() == [[16, 11, 3]]


def test_a_species_improving_after_stagnating_is_still_penalised_in_that_generation():
    # Species 2 last improved 20 generations ago and improves now (fitness 6 > its record 5).
    fitness, species, sp, cfg = _three_species()
    fitness[0, 20:] = 6.0
    cfg = dataclasses.replace(cfg, stagnant_fitness_factor=0.01)
    state, _, counts, _ = _both(fitness, species, sp, cfg, 5)
    assert state.last_improved.tolist() == [[5, 5, 5]] and counts.tolist() == [[8, 6, 16]]  # the clock restarts first
    before = dataclasses.replace(cfg, stagnation_clock_before=True)  # [NEATC]: the clock as it stood
    state, _, counts, _ = _both(fitness, species, sp, before, 5)
    assert state.last_improved.tolist() == [[5, 5, 5]]  # recorded all the same, for the next generation
    assert counts.tolist() == [[18, 12, 0]]  # 3 : 2 : 6 * 0.01
    sp.last_improved[:] = torch.tensor([[0, 0, 5 - 15]])  # max_stagnation (15) generations flat: stagnant
    assert _both(fitness, species, sp, before, 5)[2].tolist() == [[18, 12, 0]]
    sp.last_improved[:] = torch.tensor([[0, 0, 5 - 14]])  # 14: not yet
    assert _both(fitness, species, sp, before, 5)[2].tolist() == [[8, 6, 16]]


def test_obliteration_marks_the_worst_old_species_for_good():
    fitness, species, sp, cfg = _three_species()
    sp.last_improved[:] = 0  # nobody stagnant
    sp.created[:] = torch.tensor([[0, 0, 0]])
    cfg = dataclasses.replace(cfg, stagnant_fitness_factor=0.01, obliterate_interval=30, obliterate_min_age=20,
                              max_stagnation=100)
    state, _, counts, _ = _both(fitness, species, sp, cfg, 28)  # NEAT C++ counts from 1: generation 29
    assert not state.obliterated.any() and counts.tolist() == [[15, 10, 5]]
    state, _, counts, _ = _both(fitness, species, sp, cfg, 29)  # generation 30: the worst, age 30
    assert state.obliterated.tolist() == [[False, False, True]] and counts[0, 2] == 0
    sp.created[:] = torch.tensor([[0, 0, 20]])  # the worst is 10 generations old: the next one up
    assert _both(fitness, species, sp, cfg, 29)[0].obliterated.tolist() == [[False, True, False]]
    sp.created[:] = 20  # none old enough: NEAT C++ walks up to the best species
    assert _both(fitness, species, sp, cfg, 29)[0].obliterated.tolist() == [[True, False, False]]
    # the mark stays while the species lives (it is penalised in later generations too) ...
    marked = dataclasses.replace(sp, obliterated=torch.tensor([[False, False, True]]))
    state, _, counts, _ = _both(fitness, species, marked, cfg, 31)
    assert state.obliterated.tolist() == [[False, False, True]] and counts[0, 2] == 0
    # ... and ends with it: speciate clears it for a slot founded anew
    g, rng = population(small_config(pop_size=30), seeds=(0,))
    marked = dataclasses.replace(_state(1, 3), obliterated=torch.tensor([[True, True, True]]))
    _, after = speciate(g, marked, cfg, rng, 40, fused=False)
    assert not after.obliterated.any()


# --- 2. whole-population stagnation: the two best species get every offspring ------------
def test_after_twenty_flat_generations_only_the_two_best_species_breed():
    fitness, species, sp, cfg = _three_species(pop=31)
    sp.last_improved[:] = 0
    cfg = dataclasses.replace(cfg, population_stagnation=20)
    sp.run_best[:] = 10.0  # never reached in this generation
    sp.run_stale[:] = 18
    state, _, counts, _ = _both(fitness, species, sp, cfg, 7)
    assert state.run_stale.tolist() == [19] and (counts > 0).sum() == 3
    sp.run_stale[:] = 19
    state, survivors, counts, _ = _both(fitness, species, sp, cfg, 7)
    assert counts.tolist() == [[15, 16, 0]] and survivors.tolist() == [[True, True, False]]
    assert state.run_stale.tolist() == [0] and state.last_improved.tolist() == [[7, 7, 0]]
    off = _both(fitness, species, sp, dataclasses.replace(cfg, population_stagnation=0), 7)
    assert (off[2] > 0).sum() == 3 and off[0].run_stale.tolist() == [20]  # counted even when off
    sp.run_best[:] = 1.0  # a new record resets the count
    assert _both(fitness, species, sp, cfg, 7)[0].run_stale.tolist() == [0]
    alone = _state(1, 3)
    alone.alive[0, 1] = True
    alone.run_stale[:] = 19
    alone.run_best[:] = 10.0
    counts = _both(fitness, torch.ones_like(species), alone, cfg, 7)[2]
    assert counts.tolist() == [[0, 31, 0]]  # one species: all of them


def test_the_driver_delta_codes_a_flat_run_and_checkpoints_its_count(tmp_path):
    cfg = small_config(pop_size=40, population_stagnation=20, compatibility_threshold=0.5, species_elitism=0,
                       stagnant_fitness_factor=0.01)
    neat = NEAT(cfg, seeds=[0])
    g = torch.Generator().manual_seed(0)
    first = torch.rand(1, 40, generator=g, dtype=torch.float64) + 5.0
    neat.tell(first)
    for _ in range(19):
        neat.tell(torch.rand(1, 40, generator=g, dtype=torch.float64))  # never the first generation's best
    assert neat.species_state.run_stale.tolist() == [19]
    path = neat.save_checkpoint(tmp_path / "c.pt")
    back = NEAT.restore(path)
    assert back.species_state.run_stale.tolist() == [19] and back.species_state.run_best.tolist() == [
        float(first.max())]
    assert int(neat.species_state.alive.sum()) > 2
    seen = []

    class Offspring(BaseReporter):
        def end_generation(self, status):
            seen.append(status.offspring.clone())

    neat.add_reporter(Offspring())
    neat.tell(torch.rand(1, 40, generator=g, dtype=torch.float64))  # the 20th generation without a record
    assert int((seen[-1] > 0).sum()) == 2 and int(seen[-1].sum()) == 40
    assert neat.species_state.run_stale.tolist() == [0]
    # a checkpoint written before these fields existed still loads, with fresh counts
    data = neat.state_dict()
    for key in ("obliterated", "run_best", "run_stale"):
        del data["species_state"][key]
    bad = neat.state_dict()
    bad["species_state"]["run_stale"] = torch.zeros(3, dtype=torch.long)
    with pytest.raises(CheckpointError, match="run_stale should have shape"):
        NEAT.from_state_dict(bad)
    old = NEAT.from_state_dict(data)
    assert old.species_state.run_stale.tolist() == [0] and old.species_state.obliterated.shape == (1, old.species_state.capacity)


def test_delta_coding_breeds_clones_of_the_two_champions():
    cfg = small_config(pop_size=40, max_hidden=8, population_stagnation=20, node_add_prob=0.5, conn_add_prob=0.5,
                       sigma_mutate_rate=1.0, sigma_init_stdev=0.5, compatibility_threshold=0.3)
    g, rng = population(cfg, seeds=(4,))
    species, sp = speciate(g, empty_species(1, cfg.num_nodes, 4, device=g.device, dtype=g.weight.dtype), cfg, rng, 0,
                           fused=False)
    assert int(sp.alive.sum()) > 2
    fitness = torch.rand(1, 40, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    sp.run_best[:], sp.run_stale[:] = 2.0, 19
    out = []
    for fused in _fuseds():
        r = RunRNG([4])
        out.append(reproduce(g, fitness, species, sp, cfg, r, 7, fused=fused))
    children, elite, _, info = out[0]
    for other in out[1:]:
        _equal(children, other[0])
        assert torch.equal(elite, other[1])
    assert int((info.offspring > 0).sum()) == 2
    best = [int(torch.where(species == s, fitness, -1.0).argmax()) for s in torch.nonzero(info.offspring[0]).flatten()]
    champ_sigma = g.sigma[0, best]
    assert bool(torch.isin(children.sigma, champ_sigma).all())  # no sigma mutation, no crossover
    assert int(elite.sum()) == 2  # the last clone of each, as it is
    for k in torch.nonzero(elite[0]).flatten():
        assert any(torch.equal(children.weight[0, k], g.weight[0, b]) for b in best)
    # every other clone: the champion's genes, all weights changed or one gene more
    superset = [(children.conn[0] | g.conn[0, b]).eq(children.conn[0]).flatten(1).all(-1) for b in best]
    assert bool((superset[0] | superset[1]).all())
    grew = children.conn[0].flatten(1).sum(-1) > g.conn[0, best[0]].sum()
    assert 0 < int(grew.sum()) < 20  # a new link for about a fifth


# --- 3. mutation structure: exclusive mutations, children of crossover left as they are --
def _bred(cfg, fused, seed=0, generations=3):
    """A few generations of random fitness; returns (parents, children) of the last one."""
    g, rng = population(cfg, seeds=(seed, seed + 1))
    sp = empty_species(2, cfg.num_nodes, 4, device=g.device, dtype=g.weight.dtype)
    species, sp = speciate(g, sp, cfg, rng, 0, fused=fused)
    for gen in range(generations):
        parents = g
        fitness = rng.rand(cfg.pop_size, dtype=torch.float64)
        g, _, sp, _ = reproduce(g, fitness, species, sp, cfg, rng, gen, fused=fused)
        species, sp = speciate(g, sp, cfg, rng, gen + 1, fused=fused)
    return parents, g


def _fuseds():
    return [False] + ([True] if breed_kernel.kernel_available() else [])


def _equal(a, b):
    for name, t in a.tensors().items():
        assert torch.equal(t, getattr(b, name)), name


@pytest.mark.parametrize(("node", "conn"), [(1.0, 0.0), (0.0, 1.0), (1.0, 1.0)])
def test_a_structural_mutation_excludes_the_others(node, conn):
    # Sigma mutates in every child (rate 1) unless a structural mutation took its place.
    base = dict(pop_size=30, max_hidden=30, node_add_prob=node, conn_add_prob=conn, sigma_mutate_rate=1.0,
                sigma_init_stdev=0.5, crossover_prob=0.0, elitism=0)
    for exclusive in (False, True):
        out = [_bred(small_config(**base, mutation_exclusive=exclusive), fused) for fused in _fuseds()]
        parents, children = out[0]
        for other in out[1:]:
            _equal(children, other[1])
        inherited = torch.isin(children.sigma, parents.sigma)
        assert bool(inherited.all()) == exclusive, exclusive


def test_mate_only_children_of_crossover_carry_their_parents_genes():
    base = dict(pop_size=40, max_hidden=40, node_add_prob=1.0, conn_add_prob=1.0, weight_mutate_rate=1.0,
                crossover_prob=1.0, elitism=0, interspecies_crossover_prob=0.0, compatibility_threshold=100.0)
    for mate_only in (0.0, 1.0):
        out = [_bred(small_config(**base, mate_only_prob=mate_only), fused) for fused in _fuseds()]
        parents, children = out[0]
        for other in out[1:]:
            _equal(children, other[1])
        # a child's genes are its fitter parent's, and every weight one of its parents'
        same_genes = (children.conn.unsqueeze(2) == parents.conn.unsqueeze(1)).flatten(3).all(-1).any(-1)
        weights_known = ((children.weight.unsqueeze(2) == parents.weight.unsqueeze(1)) |
                         ~children.conn.unsqueeze(2)).any(2).flatten(2).all(-1)
        kept = same_genes & weights_known
        if mate_only:  # all but the clones of a parent with itself (mutated: NEAT C++ does so too)
            assert float(kept.float().mean()) > 0.7
        else:
            assert not kept.any()


# --- 4. NEAT C++'s weight perturbation ---------------------------------------------------
def test_neatc_weight_steps_are_uniform_within_the_power_and_severe_genomes_keep_some():
    cfg = small_config(pop_size=4000, weight_mutate_rate=1.0, weight_mutate_power=0.5, weight_mutate_neatc=True)
    g, rng = population(cfg, seeds=(3,))
    g.weight = torch.where(g.conn, 0.0, g.weight)  # 3 genes per genome: no tail
    everyone = torch.ones(1, cfg.pop_size, dtype=torch.bool)
    severe = torch.arange(cfg.pop_size).unsqueeze(0) % 2 == 0
    out = mutate_weights(g, cfg, rng, everyone, severe)
    w, c = out.weight[g.conn.expand_as(out.conn)], g.conn.expand_as(out.conn)
    assert float(w.abs().max()) <= 0.5  # a step uniform in +-power, perturbed or replaced
    mild, harsh = out.weight[0, 1::2][c[0, 1::2]], out.weight[0, ::2][c[0, ::2]]
    assert bool((mild != 0).all())  # not severe, no tail: every gene perturbed
    assert 0.07 < float((harsh == 0).float().mean()) < 0.13  # severe: 10 % kept
    gauss = mutate_weights(g, dataclasses.replace(cfg, weight_mutate_neatc=False), RunRNG([3]), everyone)
    assert float(gauss.weight[c].abs().max()) > 0.5  # [NEAT02]'s Gaussian steps are unbounded
    if breed_kernel.kernel_available():  # the kernel's weights: the same
        for neatc in (False, True):
            _equal(*[_bred(small_config(pop_size=30, max_hidden=12, node_add_prob=0.3, conn_add_prob=0.5,
                                        weight_mutate_neatc=neatc), fused, generations=8)[1]
                     for fused in (False, True)])


def test_neatc_weight_mutation_treats_the_last_fifth_of_a_long_genome_apart():
    cfg = small_config(num_inputs=5, num_outputs=3, pop_size=3000, weight_mutate_rate=1.0,
                       weight_mutate_neatc=True)  # 6 x 3 = 18 genes: the last 3 (index > 14.4) the tail
    g, rng = population(cfg, seeds=(1,))
    g.weight = torch.where(g.conn, 0.0, g.weight)
    everyone = torch.ones(1, cfg.pop_size, dtype=torch.bool)
    out = mutate_weights(g, cfg, rng, everyone, torch.zeros_like(everyone))
    slots = torch.nonzero(g.conn[0, 0].flatten()).squeeze(1)
    kept = (out.weight[0].flatten(1)[:, slots] == 0).float().mean(0)
    assert bool((kept[:15] == 0).all()) and bool(((kept[15:] > 0.25) & (kept[15:] < 0.35)).all())


# --- 5. multipoint crossover averaging matching weights ----------------------------------
def test_the_averaging_crossover_gives_the_mean_of_matching_weights():
    cfg = small_config(pop_size=50, crossover_average_prob=1.0)
    g, rng = population(cfg, seeds=(0,))
    other = g.gather(torch.roll(torch.arange(50), 1).unsqueeze(0))
    everyone = torch.ones(1, 50, dtype=torch.bool)
    child = crossover(g, other, cfg, rng, everyone, everyone)
    matching = g.conn & other.conn
    assert bool(matching.any())
    assert torch.equal(child.weight[matching], ((g.weight + other.weight) / 2)[matching])
    assert torch.equal(child.weight[g.conn & ~matching], g.weight[g.conn & ~matching])
    plain = crossover(g, other, cfg, RunRNG([0]), everyone)
    assert not torch.equal(plain.weight[matching], child.weight[matching])
    base = dict(pop_size=40, crossover_prob=1.0, node_add_prob=0.0, conn_add_prob=0.0, weight_mutate_rate=0.0,
                sigma_mutate_rate=0.0, enabled_mutate_rate=0.0, elitism=0, compatibility_threshold=100.0)
    for average in (0.0, 1.0):  # bred: every weight a parent's, or means of parents'
        out = [_bred(small_config(**base, crossover_average_prob=average), fused) for fused in _fuseds()]
        parents, children = out[0]
        for o in out[1:]:
            _equal(children, o[1])
        known = ((children.weight.unsqueeze(2) == parents.weight.unsqueeze(1)) |
                 ~children.conn.unsqueeze(2)).any(2).flatten(2).all(-1)
        assert bool(known.all()) == (average == 0.0)


# --- 6. new links by recurrence; one gene toggled, one re-enabled ------------------------
def _grown(cfg, seed=0):
    """Genomes with hidden nodes, extra genes and some disabled ones."""
    g, rng = population(cfg, seeds=(seed,))
    everyone = torch.ones(1, cfg.pop_size, dtype=torch.bool)
    grow = dataclasses.replace(cfg, node_add_prob=1.0, conn_add_prob=1.0, conn_add_recurrence=False)
    for _ in range(3):
        g = mutate_add_node(g, grow, rng, everyone)[0]
        g = mutate_add_connection(g, grow, rng, everyone)
    g.enabled &= torch.rand(g.enabled.shape, generator=torch.Generator().manual_seed(seed)) < 0.7
    return g, rng, everyone


@pytest.mark.parametrize("recur", [0.0, 1.0])
def test_new_links_are_recurrent_or_not_as_drawn(recur):
    cfg = small_config(pop_size=300, max_hidden=6, conn_add_prob=1.0, conn_add_recurrence=True,
                       recur_only_prob=recur)
    g, rng, everyone = _grown(cfg)
    rec = recurrent_slots(g, cfg)
    for option in (True, False):
        c = dataclasses.replace(cfg, conn_add_recurrence=option)
        out = mutate_add_connection(g, c, RunRNG([9]), everyone,
                                    recurrent=everyone if recur else ~everyone)
        new = out.conn & ~g.conn
        assert int(new.sum()) > 100
        kinds = rec[new]
        if option:
            assert bool(kinds.all()) if recur else not kinds.any()
        else:
            assert kinds.any() and not kinds.all()
    idx = torch.arange(cfg.num_nodes)
    out_node = cfg.first_output
    assert bool(rec[..., out_node, :].all()) and bool(rec[..., :, out_node].all())  # outputs' links
    assert bool(rec[..., idx, idx].all())  # self-loops


def _neat121_link_draws(cand, node, recurrent, tries, first_output, draws, seed):
    """NEAT C++ 1.2.1's ``mutate_add_link`` loop written out (an independent reference): ``draws``
    runs of up to ``tries`` tries on one genome, the slot each took (-1: none)."""
    import random

    rnd = random.Random(seed)
    present = [i for i in range(len(node)) if node[i]]
    targets = [j for j in present if j >= first_output]
    out = []
    for _ in range(draws):
        took = -1
        for _ in range(tries):
            if recurrent and rnd.random() > 0.5:  # a loop: node1 = node2, a random non-sensor
                i = j = rnd.choice(targets)
            else:
                i, j = rnd.choice(present), rnd.choice(targets)
            if cand[i][j]:
                took = i * len(node) + j
                break
        out.append(took)
    return out


@pytest.mark.parametrize("recur", [False, True])
def test_new_links_are_drawn_as_neat_121s_tries_draw_them(recur):
    from scipy.stats import chi2_contingency

    cfg = small_config(pop_size=4000, max_hidden=6, conn_add_prob=1.0, conn_add_recurrence=True,
                       recur_only_prob=1.0 if recur else 0.0, conn_add_tries=3)
    g, _, everyone = _grown(cfg)
    kinds = add_connection_candidates(g, cfg) & (recurrent_slots(g, cfg) == recur)
    p = int(kinds.flatten(2).sum(-1)[0].argmax())  # the genome with the most free slots of the kind
    one = Genomes(*(t[:, p:p + 1].expand(1, cfg.pop_size, *t.shape[2:]).clone() for t in g.tensors().values()))
    drawn = torch.full((1, cfg.pop_size), recur)
    out = mutate_add_connection(one, cfg, RunRNG([5]), everyone, recurrent=drawn)
    new = (out.conn & ~one.conn).flatten(2)[0]
    ours = torch.where(new.any(1), new.to(torch.int8).argmax(1), -1).tolist()
    cand = add_connection_candidates(one, cfg)[0, 0] & (recurrent_slots(one, cfg)[0, 0] == recur)
    ref = _neat121_link_draws(cand.tolist(), one.node[0, 0].tolist(), recur, 3, cfg.first_output, cfg.pop_size, 1)
    slots = sorted(set(ours) | set(ref))
    assert len(slots) >= 4 and -1 in ref  # several slots, and failures: 3 tries miss often
    table = [[ours.count(s) for s in slots], [ref.count(s) for s in slots]]
    assert chi2_contingency(table).pvalue > 1e-3, table
    # the uniform pick among free slots is another distribution, which this test tells apart
    uniform = mutate_add_connection(one, dataclasses.replace(cfg, conn_add_tries=0), RunRNG([5]), everyone,
                                    recurrent=drawn)
    new = (uniform.conn & ~one.conn).flatten(2)[0]
    flat = torch.where(new.any(1), new.to(torch.int8).argmax(1), -1).tolist()
    assert chi2_contingency([[flat.count(s) for s in slots], table[1]]).pvalue < 1e-6


def test_one_gene_toggles_and_the_first_disabled_gene_comes_back():
    cfg = small_config(pop_size=300, max_hidden=6, toggle_enable_prob=1.0)
    g, rng, everyone = _grown(cfg, seed=2)
    out = mutate_toggle_one(g, cfg, rng, everyone)
    changed = (out.enabled != g.enabled).flatten(2).sum(-1)
    assert int(changed.max()) == 1 and float((changed == 1).float().mean()) > 0.5
    disabled_now = g.enabled & ~out.enabled  # only where another enabled gene leaves the source
    r, p, i, j = torch.nonzero(disabled_now, as_tuple=True)
    assert bool(((out.conn & out.enabled)[r, p, i].sum(-1) >= 1).all()) and len(r) > 0
    # the initial genomes: one gene per source, so none is ever disabled
    g0, rng0 = population(cfg, seeds=(0,))
    assert torch.equal(mutate_toggle_one(g0, cfg, rng0, everyone).enabled, g0.enabled)
    cfg = small_config(pop_size=300, max_hidden=6, gene_reenable_prob=1.0)
    out = mutate_toggle_one(g, cfg, RunRNG([4]), everyone)
    off = (g.conn & ~g.enabled).flatten(2)
    back = (out.enabled & ~g.enabled).flatten(2)
    assert torch.equal(back.sum(-1), off.any(-1).long())  # one gene per genome that had one off ...
    first = off.to(torch.int8).argmax(-1)
    has = off.any(-1)
    assert bool(torch.gather(back, 2, first.unsqueeze(-1)).squeeze(-1)[has].all())  # ... the first
    per_gene = mutate_toggle_enabled(g, small_config(pop_size=300, max_hidden=6, enabled_mutate_rate=0.5),
                                     RunRNG([4]), everyone)
    assert int((per_gene.enabled != g.enabled).flatten(2).sum(-1).max()) > 1  # the per-gene rule: many


# --- presets -----------------------------------------------------------------------------
def test_the_presets_transcribe_the_two_parameter_files():
    dpv = neat121_config("dpv", num_inputs=4, num_outputs=1)
    dpnv = neat121_config("neat-1.2.1-dpnv", num_inputs=2, num_outputs=1)
    assert (dpv.pop_size, dpv.weight_mutate_power, dpv.compatibility_threshold, dpv.survival_threshold) == (
        150, 2.5, 3.0, 0.2)
    assert (dpv.node_add_prob, dpv.conn_add_prob, dpv.mate_only_prob, dpv.crossover_average_prob) == (
        0.03, 0.05, 0.2, 0.4)
    assert (dpv.crossover_prob, dpv.weight_mutate_rate, dpv.max_stagnation, dpv.population_stagnation) == (
        0.75, 0.9, 14, 20)  # penalised from 14 generations without improvement: dropoff_age 15
    differ = {k for k in NEAT121_DPV if NEAT121_DPV[k] != NEAT121_DPNV[k]}
    assert differ == {"pop_size", "weight_mutate_power", "compatibility_weight_coefficient",
                      "compatibility_threshold", "survival_threshold", "weight_mutate_rate", "node_add_prob",
                      "conn_add_prob", "toggle_enable_prob", "gene_reenable_prob", "recur_only_prob"}
    assert (dpnv.toggle_enable_prob, dpnv.gene_reenable_prob, dpnv.recur_only_prob) == (0.1, 0.05, 0.2)
    assert (dpnv.pop_size, dpnv.weight_mutate_power, dpnv.compatibility_weight_coefficient) == (1000, 1.8, 3.0)
    assert dpv.bias_value == dpnv.bias_value == 0.5  # the experiments' bias input, input[...] = .5
    assert not {"num_inputs", "num_outputs", "num_bias"} & (set(NEAT121_DPV) | set(NEAT121_DPNV))
    assert neat121_config("dpv", pop_size=20).pop_size == 20
    with pytest.raises(ConfigError, match="variant must be one of"):
        neat121_config("dpx")
    with pytest.raises(ConfigError, match="mate_only_prob"):
        neat121_config("dpv", mate_only_prob=2.0)


@needs_kernel
@pytest.mark.parametrize("variant", ["dpv", "dpnv"])
@pytest.mark.parametrize("tries", [0, 20])
def test_kernels_breed_the_reference_generations_under_the_presets(variant, tries):
    # A controller's layout (four inputs and a bias, recurrent), the preset's GA (shared new-link
    # weights, uniform new weights and NEAT's parents included), populations small enough to be
    # quick; structure grows, species form, go stagnant and are penalised.
    cfg = neat121_config(variant, num_inputs=4, num_outputs=1, num_bias=1, max_hidden=12, pop_size=60,
                         node_add_prob=0.1, conn_add_prob=0.3, max_stagnation=3, population_stagnation=4,
                         obliterate_interval=5, obliterate_min_age=3, compatibility_threshold=1.5,
                         conn_add_tries=tries)
    g = torch.Generator().manual_seed(1)
    ref, fast = bred_on_both_paths(cfg, [5, 6], [
        (torch.rand(2, cfg.pop_size, generator=g, dtype=torch.float64) * (3 if k < 3 else 1),) for k in range(14)])
    assert_same_breeding(ref, fast)
    assert int(ref.genomes.conn.flatten(2).sum(-1).max()) >= 10  # long genomes: the tail rule ran


# --- speciation: first fit against the champions ---------------------------------------
@pytest.mark.parametrize("fused", [False, pytest.param(True, marks=needs_kernel)])
def test_a_genome_joins_the_oldest_compatible_species_not_the_closest(fused):
    cfg = small_config(pop_size=3, compatibility_threshold=3.0, compatibility_weight_coefficient=1.0)
    g, rng = population(cfg, seeds=(0,))
    sp = empty_species(1, cfg.num_nodes, 4, device=g.device, dtype=g.weight.dtype)
    # two living species whose representatives are genome 0 with every weight shifted: slot 0,
    # founded later (number 7), by 0.25; slot 1, founded first (number 3), by 1.0; both within
    # the threshold, slot 0 the closer
    sp.alive[0, :2] = True
    sp.ident[0, :2] = torch.tensor([7, 3])
    sp.next_id[0] = 8
    for s, shift in ((0, 0.25), (1, 1.0)):
        sp.rep_conn[0, s], sp.rep_sigma[0, s] = g.conn[0, 0], g.sigma[0, 0]
        sp.rep_weight[0, s] = torch.where(g.conn[0, 0], g.weight[0, 0] + shift, 0.0)
    closest, _ = speciate(g, sp, cfg, RunRNG([1]), 1, fused=fused)
    first, _ = speciate(g, sp, dataclasses.replace(cfg, speciate_neatc=True), RunRNG([1]), 1, fused=fused)
    assert int(closest[0, 0]) == 0 and int(first[0, 0]) == 1  # the closest, and the oldest within reach
    far = dataclasses.replace(cfg, speciate_neatc=True)
    sp.rep_weight[0, 1] = torch.where(g.conn[0, 0], g.weight[0, 0] + 5.0, 0.0)  # the old one out of reach
    assert int(speciate(g, sp, far, RunRNG([1]), 1, fused=fused)[0][0, 0]) == 0


def test_the_representatives_are_the_species_champions_of_the_evaluated_generation():
    from evolution.reproduce import champion_representatives

    cfg = small_config(pop_size=8, max_hidden=6, speciate_neatc=True)
    g, _, _ = _grown(cfg)
    species = torch.tensor([[0, 0, 1, 1, 1, 0, 2, 2]])
    fitness = torch.tensor([[1.0, 3.0, 2.0, 2.0, 0.5, 3.0, -torch.inf, -torch.inf]])
    sp = empty_species(1, cfg.num_nodes, 4, device=g.device, dtype=g.weight.dtype)
    sp.alive[0, :3] = True
    out = champion_representatives(g, fitness, species, sp)
    for slot, champion in ((0, 1), (1, 2), (2, 6)):  # the best member, the first on ties
        assert torch.equal(out.rep_conn[0, slot], g.conn[0, champion])
        assert torch.equal(out.rep_weight[0, slot], g.weight[0, champion])
        assert out.rep_sigma[0, slot] == g.sigma[0, champion]
    assert not out.rep_conn[0, 3].any() and torch.equal(sp.rep_conn, torch.zeros_like(sp.rep_conn))  # pure
    # runs=: g holds more runs than the others describe
    two = Genomes(*(torch.cat([t, t.flip(1)]) for t in g.tensors().values()))
    picked = champion_representatives(two, fitness, species, sp, runs=torch.tensor([1]))
    assert torch.equal(picked.rep_weight[0, 0], g.weight[0, cfg.pop_size - 1 - 1])


# --- validation ------------------------------------------------------------------------
@pytest.mark.parametrize(("field", "value"), [
    ("stagnant_fitness_factor", -0.1), ("stagnant_fitness_factor", 1.5), ("obliterate_interval", -1),
    ("obliterate_min_age", 0), ("population_stagnation", -2), ("population_stagnation", 2.5),
    ("mutation_exclusive", 1), ("mate_only_prob", 1.1), ("crossover_average_prob", -0.5),
    ("weight_mutate_neatc", "yes"), ("recur_only_prob", 2.0), ("toggle_enable_prob", -1.0),
    ("gene_reenable_prob", float("nan")), ("conn_add_recurrence", None), ("conn_add_tries", -1),
    ("conn_add_tries", 2.5), ("speciate_neatc", 1), ("weight_init_uniform", 1), ("conn_add_shared_weight", "yes"), ("survival_neatc", 0),
    ("stagnation_clock_before", 1), ("compat_mutation_num", "on"), ("node_add_neatc", 0),
])
def test_bad_values_name_their_field(field, value):
    with pytest.raises(ConfigError, match=field):
        NEATConfig(**{field: value})


def test_two_weight_rules_at_once_are_refused():
    with pytest.raises(ConfigError, match="weight_mutate_neatc and weight_mutate_per_gene"):
        NEATConfig(weight_mutate_neatc=True, weight_mutate_per_gene=True)


# --- C against the tensor reference with every mechanism on ----------------------------
@needs_kernel
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("first_fit", [False, True])
def test_kernels_breed_the_reference_generations_with_the_mechanisms_on(dtype, first_fit):
    cfg = small_config(speciate_neatc=first_fit, pop_size=50, max_hidden=6, node_add_prob=0.2, conn_add_prob=0.3, enabled_mutate_rate=0.05,
                       compatibility_threshold=1.0, species_elitism=0, max_stagnation=3,
                       stagnant_fitness_factor=0.01, obliterate_interval=4, obliterate_min_age=2,
                       population_stagnation=3, mutation_exclusive=True, mate_only_prob=0.2,
                       weight_mutate_neatc=True, crossover_average_prob=0.4, conn_add_recurrence=True,
                       recur_only_prob=0.3, toggle_enable_prob=0.3, gene_reenable_prob=0.2)
    g = torch.Generator().manual_seed(7)
    tells = []
    for k in range(12):
        solved = torch.zeros(2, cfg.pop_size, dtype=torch.bool)
        solved[1, 0] = k == 8
        tells.append((torch.rand(2, cfg.pop_size, generator=g, dtype=torch.float64) * (1 + (k % 3 == 0)), solved))
    ref, fast = bred_on_both_paths(cfg, [3, 11], tells, dtype=dtype)
    assert_same_breeding(ref, fast)
    assert torch.equal(ref.rng.offsets, fast.rng.offsets)
    assert ref.species_state.obliterated.any() or ref.species_state.run_stale.max() < 3


def test_the_c_draw_blocks_are_the_python_ones_in_order():
    # breed.c addresses the draws by its B_* enum; breed_kernel lays the blocks out: the same order.
    text = (Path(breed_kernel.__file__).parent / "csrc" / "breed.c").read_text()
    body = re.search(r"enum \{ (B_FROM_OTHER[^}]*)\};", text).group(1)
    names = [w.strip() for w in re.sub(r"/\*.*?\*/", "", body, flags=re.S).split(",") if w.strip()]
    python = [n for n, _, _ in breed_kernel._BLOCKS + breed_kernel._TOGGLE_ONE_BLOCKS]
    assert names[-1] == "N_BLOCKS" and len(names) - 1 == len(python)
    assert names[-4:-1] == ["B_ONE_WANT", "B_ONE_PICK", "B_REENABLE"]
    starts, total = breed_kernel.breed_blocks(5, 3, small_config(toggle_enable_prob=0.1))
    assert len(starts) == len(python) and total == breed_kernel.breed_blocks(5, 3)[1] + 3 * 5


# --- uniform initial weights ([NEATC]'s +-1, neat-python's weight_init_type) ------------
def _new_weights_everywhere(cfg):
    """Weights a start population draws, new links draw and per-gene replacements draw."""
    g, rng = population(cfg, seeds=(0, 1))
    start = g.weight[g.conn]
    everyone = torch.ones(2, cfg.pop_size, dtype=torch.bool)
    linked = mutate_add_connection(g, cfg, rng, everyone)
    new_links = linked.weight[linked.conn & ~g.conn]
    replaced = mutate_weights(g, dataclasses.replace(cfg, weight_replace_rate=1.0, weight_mutate_rate=0.0,
                                                     weight_mutate_per_gene=True), rng, everyone)
    return start, new_links, replaced.weight[g.conn]


def test_uniform_initial_weights_fill_neat_pythons_bounds_where_gaussian_ones_spill_over():
    cfg = small_config(num_inputs=4, pop_size=200, max_hidden=6, conn_add_prob=1.0, weight_init_stdev=0.5)
    uniform = dataclasses.replace(cfg, weight_init_uniform=True)
    for drawn in _new_weights_everywhere(uniform):
        assert drawn.numel() > 150
        assert float(drawn.min()) >= -1.0 and float(drawn.max()) < 1.0  # mean +- 2 stdev
        assert float(drawn.min()) < -0.9 and float(drawn.max()) > 0.9
        # flat, not bell-shaped: as many in the outer half as in the inner half
        assert abs(float((drawn.abs() > 0.5).double().mean()) - 0.5) < 0.1
    for drawn in _new_weights_everywhere(cfg):  # Gaussian with stdev 0.5: 5 % beyond +-1
        assert float((drawn.abs() > 1.0).double().mean()) > 0.01
    # the bounds are cut to [weight_min_value, weight_max_value]
    narrow = dataclasses.replace(uniform, weight_init_mean=7.5, weight_init_stdev=1.0)
    for drawn in _new_weights_everywhere(narrow):
        assert float(drawn.min()) >= 5.5 and float(drawn.max()) <= 8.0 and float(drawn.max()) > 7.8


def test_random_genomes_draw_uniform_weights_too():
    from evolution.population import random_genomes

    cfg = small_config(pop_size=50, weight_init_uniform=True, weight_init_mean=1.0, weight_init_stdev=0.25)
    g = random_genomes(cfg, runs=2, hidden=2, density=0.8, seed=3)
    w = g.weight[g.conn]
    assert float(w.min()) >= 0.5 and float(w.max()) < 1.5 and float(w.max()) - float(w.min()) > 0.9


def test_the_ini_weight_init_type_sets_weight_init_uniform(tmp_path):
    path = tmp_path / "neat.ini"
    for text, uniform in (("uniform", True), ("gaussian", False), ("Normal", False)):
        path.write_text(f"[DefaultGenome]\nnum_inputs = 2\nnum_outputs = 1\nweight_init_type = {text}\n")
        assert NEATConfig.from_ini(path).weight_init_uniform is uniform
    path.write_text("[DefaultGenome]\nweight_init_type = cauchy\n")
    with pytest.raises(ConfigError, match="weight_init_type must be gaussian, normal or uniform"):
        NEATConfig.from_ini(path)
    with pytest.raises(ConfigError, match="weight_init_uniform"):
        NEATConfig(weight_init_uniform="uniform")


@needs_kernel
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("per_gene", [False, True])
def test_kernels_breed_the_reference_generations_with_uniform_initial_weights(dtype, per_gene):
    cfg = small_config(pop_size=40, max_hidden=6, node_add_prob=0.2, conn_add_prob=0.5, weight_init_uniform=True,
                       weight_init_stdev=0.5, weight_mutate_per_gene=per_gene, weight_replace_rate=0.3,
                       compatibility_threshold=1.0)
    g = torch.Generator().manual_seed(4)
    ref, fast = bred_on_both_paths(cfg, [2, 9], [
        (torch.rand(2, cfg.pop_size, generator=g, dtype=torch.float64),) for _ in range(8)], dtype=dtype)
    assert_same_breeding(ref, fast)


# --- a generation's new links share their weight ([NEATC]'s innovation list) -----------
def test_a_link_added_again_in_the_same_generation_takes_the_first_ones_weight():
    # The start genomes' only free slot is the output's self-loop: every genome adds it.
    cfg = small_config(pop_size=12, max_hidden=0, conn_add_prob=1.0)
    g, _ = population(cfg, seeds=(0, 1))
    everyone = torch.ones(2, cfg.pop_size, dtype=torch.bool)
    loop = (cfg.first_output, cfg.first_output)
    own = mutate_add_connection(g, cfg, RunRNG([4, 5]), everyone).weight[..., loop[0], loop[1]]
    shared_cfg = dataclasses.replace(cfg, conn_add_shared_weight=True)
    shared = mutate_add_connection(g, shared_cfg, RunRNG([4, 5]), everyone).weight[..., loop[0], loop[1]]
    assert own[0].unique().numel() == cfg.pop_size  # each its own draw
    assert torch.equal(shared, own[:, :1].expand_as(own))  # the first child's draw, run by run
    assert shared[0, 0] != shared[1, 0]
    # only genomes that add the same slot share: two free slots, two weights per run
    two = small_config(pop_size=40, max_hidden=1, conn_add_prob=1.0, conn_add_shared_weight=True)
    g, _ = population(two, seeds=(3,))
    g.node[..., two.first_hidden] = True  # a lone hidden node: more free slots
    out = mutate_add_connection(g, two, RunRNG([6]), torch.ones(1, two.pop_size, dtype=torch.bool))
    new = out.conn & ~g.conn
    for slot in torch.nonzero(new.any(1)[0]):
        weights = out.weight[0][:, slot[0], slot[1]][new[0][:, slot[0], slot[1]]]
        assert weights.unique().numel() == 1
    assert out.weight[0][new[0]].unique().numel() == int(new.any(1).sum()) > 1


# --- parents per species: NEAT 1.2.1's floor(s * size + 1) -----------------------------
@pytest.mark.parametrize("select", ["tensor", "kernel"])
def test_neatc_survival_keeps_floor_s_size_plus_one_parents(select):
    if select == "kernel" and not select_kernel.kernel_available():
        pytest.skip("no C compiler: kernels unavailable")
    pick = select_parents if select == "tensor" else select_kernel.select_parents
    runs, P = 64, 10  # one species of 10: 0.4 * 10 = 4 is whole, so floor(4 + 1) = 5 against ceil(4) = 4
    fitness = torch.arange(P, 0, -1, dtype=torch.float64).expand(runs, P).contiguous()  # genome k ranks k
    species = torch.zeros(runs, P, dtype=torch.long)
    survivors = torch.ones(runs, 1, dtype=torch.bool)
    counts = torch.full((runs, 1), P, dtype=torch.long)
    parents = {}
    for neatc in (False, True):
        cfg = small_config(pop_size=P, survival_threshold=0.4, elitism=0, survival_neatc=neatc)
        first, second, _, _ = pick(fitness, species, survivors, counts, cfg, RunRNG(list(range(runs))))
        parents[neatc] = set(torch.cat([first, second]).flatten().tolist())
    assert parents[False] == {0, 1, 2, 3}
    assert parents[True] == {0, 1, 2, 3, 4}


def test_neatc_survival_never_keeps_more_parents_than_members():
    size = torch.tensor([1, 2, 3, 5, 10, 150])  # species with members (empty ones get none anyway)
    neatc = _parents_per_species(size, small_config(survival_threshold=1.0, survival_neatc=True))
    assert neatc.tolist() == size.tolist()  # floor(size + 1) capped at size
    ours = _parents_per_species(size, small_config(survival_threshold=0.2))
    assert ours.tolist() == [1, 1, 1, 1, 2, 30]
    assert _parents_per_species(size, small_config(survival_threshold=0.2, survival_neatc=True)).tolist() == \
        [1, 1, 1, 2, 3, 31]
