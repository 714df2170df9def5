"""The C breeding kernels against the tensor reference, and the counter-based streams."""

import dataclasses
import shutil

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from evolution.distance import distance, gene_stats
from evolution.kernels import breed as breed_kernel
from evolution.kernels import select as select_kernel
from evolution.neat import NEAT
from evolution.reproduce import (
    _rep_nodes,
    allocate_offspring,
    reproduce,
    select_parents,
    species_offspring,
    update_stagnation,
)
from evolution.rng import RunRNG, _cos_2pi, _log_unit, _sqrt, box_muller
from evolution.speciate import SpeciesState, empty_species, speciate
from snn_torch.kernels.build import kernels_enabled
from tasks.studies.cartpole import controller_config
from tasks.studies.xor import XOR_CONFIG
from tests.evolution import kernel_entry_points as kernel_tests
from tests.evolution.helpers import population, small_config

needs_kernel = pytest.mark.skipif(not breed_kernel.kernel_available(), reason="no C compiler: kernels unavailable")


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
@pytest.mark.skipif(not kernels_enabled(), reason="kernels disabled (SNN_NEAT_C_KERNELS=0)")
def test_the_kernels_compile_where_a_compiler_is():
    # Else every kernel test would skip, and a kernel that no longer compiles would pass CI.
    assert breed_kernel.kernel_available() and select_kernel.kernel_available()


def _equal_state(a: NEAT, b: NEAT) -> None:
    for name, t in a.genomes.tensors().items():
        assert torch.equal(t, getattr(b.genomes, name)), name
    assert torch.equal(a.species, b.species)
    for name, t in a.species_state.tensors().items():
        assert torch.equal(t, getattr(b.species_state, name)), name
    assert torch.equal(a.rng.offsets, b.rng.offsets)


@needs_kernel
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("setting", ["xor", "snn", "sigmoid"])
def test_kernel_breeds_the_same_generations_as_the_tensor_operators(setting, dtype):
    cfg = (dataclasses.replace(XOR_CONFIG, node_add_prob=0.2, conn_add_prob=0.3) if setting == "xor"
           else controller_config(setting, node_add_prob=0.1, conn_add_prob=0.3))
    runs = []
    for fused in (False, True):
        neat = NEAT(cfg, seeds=[3, 11, 12], dtype=dtype)
        neat.fused_breeding = fused
        g = torch.Generator().manual_seed(7)
        for k in range(12):
            solved = torch.zeros(3, cfg.pop_size, dtype=torch.bool)
            solved[1, 0] = k == 5  # run 1 freezes: later steps breed a subset of the runs
            neat.tell(torch.rand(3, cfg.pop_size, generator=g, dtype=torch.float64) * 16, solved)
        assert neat.solved_generation.tolist() == [-1, 6, -1]
        runs.append(neat)
    ref, fast = runs
    _equal_state(ref, fast)
    # The generations did what a test of equality needs: structure grew, species formed.
    assert ref.genomes.num_hidden(cfg).sum() > 0
    assert int(ref.species_state.alive.sum(1).min()) > 1


# [NEATC] mechanisms (evolution.neat121): off (the defaults) or on, in any combination.
NEAT121_OPTIONS = st.fixed_dictionaries({
    "stagnant_fitness_factor": st.sampled_from([0.0, 0.0, 0.01, 0.5]),
    "max_stagnation": st.sampled_from([15, 1, 2]),
    "species_elitism": st.sampled_from([2, 0]),
    "obliterate_interval": st.sampled_from([0, 0, 2, 3]),
    "obliterate_min_age": st.sampled_from([1, 2, 20]),
    "population_stagnation": st.sampled_from([0, 0, 1, 2]),
    "mutation_exclusive": st.booleans(),
    "mate_only_prob": st.sampled_from([0.0, 0.0, 0.2, 1.0]),
    "weight_mutate_neatc": st.booleans(),
    "crossover_average_prob": st.sampled_from([0.0, 0.0, 0.4, 1.0]),
    "conn_add_recurrence": st.booleans(),
    "recur_only_prob": st.sampled_from([0.0, 0.2, 1.0]),
    "toggle_enable_prob": st.sampled_from([0.0, 0.0, 0.1, 1.0]),
    "gene_reenable_prob": st.sampled_from([0.0, 0.0, 0.05, 1.0]),
    "survival_neatc": st.booleans(),
    "stagnation_clock_before": st.booleans(),
    "compat_mutation_num": st.booleans(),
    "node_add_neatc": st.booleans(),
})


@needs_kernel
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), feed_forward=st.booleans(), node_add=st.sampled_from([0.3, 1.0]),
       per_gene=st.booleans(), generations=st.integers(1, 6), neat121=NEAT121_OPTIONS)
def test_kernel_matches_reference_on_small_populations(seed, feed_forward, node_add, per_gene, generations, neat121):
    # Tiny node capacity and node_add 1.0: splits are refused for want of a slot.
    cfg = small_config(feed_forward=feed_forward, node_add_prob=node_add, conn_add_prob=0.5,
                       enabled_mutate_rate=0.1, weight_mutate_per_gene=per_gene and not neat121["weight_mutate_neatc"],
                       **neat121)
    out = []
    for fused in (False, True):
        g, rng = population(cfg, seeds=(seed, seed + 1))
        sp = empty_species(2, cfg.num_nodes, 2, device=g.device, dtype=g.weight.dtype)
        species, sp = speciate(g, sp, cfg, rng, 0, fused=fused)
        refused = []
        for gen in range(generations):
            fitness = rng.rand(cfg.pop_size, dtype=torch.float64) * 10
            g, _, sp, info = reproduce(g, fitness, species, sp, cfg, rng, gen, fused=fused)
            species, sp = speciate(g, sp, cfg, rng, gen + 1, fused=fused)
            refused.append(info.split_refused)
        out.append((g, species, sp, torch.stack(refused), rng.offsets))
    (g0, s0, sp0, r0, o0), (g1, s1, sp1, r1, o1) = out
    for name, t in g0.tensors().items():
        assert torch.equal(t, getattr(g1, name)), name
    assert torch.equal(s0, s1) and torch.equal(r0, r1) and torch.equal(o0, o1)
    for name, t in sp0.tensors().items():
        assert torch.equal(t, getattr(sp1, name)), name


@needs_kernel
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), pop=st.integers(2, 60), slots=st.integers(1, 9),
       survival=st.sampled_from([0.05, 0.1, 0.15, 0.2, 0.3, 0.7, 1.0]), elitism=st.integers(0, 3),
       elitism_min=st.integers(1, 6), tied=st.booleans(), neatc=st.booleans())
def test_selection_kernel_equals_the_tensor_selection(seed, pop, slots, survival, elitism, elitism_min, tied, neatc):
    # Small species, dead and stagnant slots, tied fitness values (ties go by index) and
    # survival thresholds whose float32 product with the size is rounded (0.3 * 10); with
    # survival_neatc, NEAT 1.2.1's floor(s * size + 1) parents.
    _check_selection(seed, pop, slots, survival, elitism, elitism_min, tied, neatc)


@needs_kernel
@pytest.mark.parametrize("pop", [512, 513, 1500])  # the kernel sorts up to 512 by rank, beyond by merging
@pytest.mark.parametrize("tied", [False, True])
def test_selection_kernel_equals_the_tensor_selection_in_large_runs(pop, tied):
    _check_selection(pop, pop, 7, 0.2, 1, 3, tied)


def _check_selection(seed, pop, slots, survival, elitism, elitism_min, tied, neatc=False):
    cfg = dataclasses.replace(small_config(pop_size=pop), survival_threshold=survival, elitism=elitism,
                              elitism_min_species_size=elitism_min, interspecies_crossover_prob=0.3,
                              survival_neatc=neatc)
    g = torch.Generator().manual_seed(seed)
    R = 3
    species = torch.randint(0, slots, (R, pop), generator=g)
    fitness = torch.randint(0, 4, (R, pop), generator=g).double() if tied else torch.rand(R, pop, generator=g,
                                                                                            dtype=torch.float64)
    sp = empty_species(R, 2, slots, device=torch.device("cpu"), dtype=torch.float32)
    sp.alive.scatter_(1, species, True)  # the slots with members live ...
    sp.last_improved[:] = torch.randint(-30, 1, (R, slots), generator=g)  # ... some of them stagnant
    _, survivors, _ = update_stagnation(fitness, species, sp, cfg, 0)
    counts = allocate_offspring(fitness, species, survivors, pop)
    out = []
    for select in (select_parents, select_kernel.select_parents):
        rng = RunRNG([seed, seed + 1, seed + 2])
        out.append((*select(fitness, species, survivors, counts, cfg, rng), rng.offsets))
    for name, a, b in zip(["first", "second", "do_cross", "elite", "offsets"], *out, strict=True):
        assert torch.equal(a, b), name


@needs_kernel
@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), pop=st.integers(2, 160), slots=st.integers(1, 130),
       fitness_kind=st.sampled_from(["tied", "uniform", "negative", "zero", "wide"]),
       stagnation=st.integers(1, 20), species_elitism=st.integers(0, 4), generation=st.integers(0, 40))
def test_species_kernel_equals_stagnation_then_allocation(seed, pop, slots, fitness_kind, stagnation,
                                                          species_elitism, generation):
    # Dead and stagnant slots, members of dead slots, ties in fitness (the protected species
    # and the largest remainders go by slot), negative and all-zero fitness (shares shifted,
    # or split evenly), fitness spread over many orders of magnitude (the shares' sum order),
    # and up to 130 slots (longer than any vector width).
    cfg = dataclasses.replace(small_config(pop_size=pop), max_stagnation=stagnation, species_elitism=species_elitism)
    g = torch.Generator().manual_seed(seed)
    R = 4
    species = torch.randint(0, slots, (R, pop), generator=g)
    fitness = {"tied": lambda: torch.randint(0, 4, (R, pop), generator=g).double(),
               "uniform": lambda: torch.rand(R, pop, generator=g, dtype=torch.float64),
               "negative": lambda: torch.rand(R, pop, generator=g, dtype=torch.float64) * 10 - 7,
               "zero": lambda: torch.zeros(R, pop, dtype=torch.float64),
               "wide": lambda: 10 ** (torch.rand(R, pop, generator=g, dtype=torch.float64) * 12 - 4)}[fitness_kind]()
    sp = empty_species(R, 2, slots, device=torch.device("cpu"), dtype=torch.float32)
    sp.alive[:] = torch.rand(R, slots, generator=g) < 0.8
    sp.alive.scatter_(1, species[:, : pop // 2], True)
    sp.best_fitness[:] = torch.where(torch.rand(R, slots, generator=g) < 0.3, -torch.inf,
                                     torch.rand(R, slots, generator=g, dtype=torch.float64))
    sp.last_improved[:] = torch.randint(-30, generation + 1, (R, slots), generator=g)
    ref_sp, ref_survivors, _ = update_stagnation(fitness, species, sp, cfg, generation)
    ref_counts = allocate_offspring(fitness, species, ref_survivors, pop)
    best, last, survivors, counts = select_kernel.species_offspring(fitness, species, sp.alive, sp.best_fitness,
                                                                   sp.last_improved, cfg, generation)
    assert torch.equal(best, ref_sp.best_fitness)
    assert torch.equal(last, ref_sp.last_improved)
    assert torch.equal(survivors, ref_survivors)
    assert torch.equal(counts, ref_counts)
    assert (counts.sum(1) == torch.where(survivors.any(1), pop, 0)).all()


@needs_kernel
@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), pop=st.integers(2, 160), slots=st.integers(1, 40),
       tied=st.booleans(), generation=st.integers(0, 40), neat121=NEAT121_OPTIONS)
def test_species_kernel_equals_the_reference_with_the_neat121_mechanisms(seed, pop, slots, tied, generation,
                                                                         neat121):
    # Penalised or removed stagnant species, obliteration (old and young species, marks
    # carried in), the run's record and delta coding, over tied and untied fitness.
    cfg = small_config(pop_size=pop, **neat121)
    g = torch.Generator().manual_seed(seed)
    R = 4
    species = torch.randint(0, slots, (R, pop), generator=g)
    fitness = (torch.randint(0, 4, (R, pop), generator=g).double() if tied
               else torch.rand(R, pop, generator=g, dtype=torch.float64))
    sp = empty_species(R, 2, slots, device=torch.device("cpu"), dtype=torch.float32)
    sp.alive[:] = torch.rand(R, slots, generator=g) < 0.8
    sp.alive.scatter_(1, species, True)
    sp.best_fitness[:] = torch.where(torch.rand(R, slots, generator=g) < 0.3, -torch.inf,
                                     torch.rand(R, slots, generator=g, dtype=torch.float64))
    sp.last_improved[:] = torch.randint(-30, generation + 1, (R, slots), generator=g)
    sp.created[:] = torch.randint(-30, generation + 1, (R, slots), generator=g)
    sp.obliterated[:] = torch.rand(R, slots, generator=g) < 0.1
    sp.run_best[:] = torch.rand(R, generator=g, dtype=torch.float64) * 1.2
    sp.run_stale[:] = torch.randint(0, 4, (R,), generator=g)
    ref = species_offspring(fitness, species, sp, cfg, generation)
    fast = select_kernel.species_state_offspring(fitness, species, sp, cfg, generation)
    for name, t in ref[0].tensors().items():
        assert torch.equal(t, getattr(fast[0], name)), name
    assert torch.equal(ref[1], fast[1]) and torch.equal(ref[2], fast[2]) and torch.equal(ref[3], fast[3])
    assert (ref[2].sum(1) == torch.where(ref[1].any(1), pop, 0)).all()


@needs_kernel
def test_species_kernel_sums_the_shares_in_the_references_order():
    # Five species of equal-valued members: the largest remainders depend on the last bit of
    # the shares' total, and a vector-order sum of these five shares gives [50, 31, 15, 50, 4].
    sizes, values = [21, 24, 38, 36, 31], [1.1, 0.7, 1 / 3, 1.1, 0.1]
    species = torch.tensor([[s for s, n in enumerate(sizes) for _ in range(n)]])
    fitness = torch.tensor([[values[s] for s, n in enumerate(sizes) for _ in range(n)]], dtype=torch.float64)
    alive = torch.ones(1, 5, dtype=torch.bool)
    counts = allocate_offspring(fitness, species, alive, 150)
    assert counts.tolist() == [[49, 31, 15, 50, 5]]
    cfg = small_config(pop_size=150)
    *_, kernel_counts = select_kernel.species_offspring(fitness, species, alive, torch.full((1, 5), -torch.inf,
                                                        dtype=torch.float64), torch.zeros(1, 5, dtype=torch.long), cfg, 0)
    assert torch.equal(kernel_counts, counts)


@needs_kernel
def test_speciating_runs_in_place_equals_speciating_a_copy_of_them():
    cfg = dataclasses.replace(XOR_CONFIG, node_add_prob=0.3, conn_add_prob=0.3)
    neat = NEAT(cfg, seeds=[1, 2, 3, 4])
    g = torch.Generator().manual_seed(3)
    for _ in range(4):
        neat.tell(torch.rand(4, cfg.pop_size, generator=g, dtype=torch.float64) * 16)
    runs = torch.tensor([1, 3])
    sp = neat.species_state.select_runs(runs)
    out = []
    for pop, rows in ((neat.genomes, runs), (neat.genomes.select_runs(runs), None)):
        rng = RunRNG([2, 4])
        out.append((*speciate(pop, sp, cfg, rng, 5, fused=True, runs=rows), rng.offsets))
    (s0, sp0, o0), (s1, sp1, o1) = out
    assert torch.equal(s0, s1) and torch.equal(o0, o1)
    for name, t in sp0.tensors().items():
        assert torch.equal(t, getattr(sp1, name)), name
    with pytest.raises(ValueError, match="in_place needs runs"):
        reproduce(neat.genomes, torch.zeros(4, cfg.pop_size, dtype=torch.float64), neat.species,
                  neat.species_state, cfg, neat.rng, 5, in_place=True)


@needs_kernel
@pytest.mark.parametrize("subset", [False, True])
def test_bred_gene_bits_are_the_childrens_and_speciate_the_same_with_them(subset):
    cfg = dataclasses.replace(XOR_CONFIG, node_add_prob=0.3, conn_add_prob=0.3, enabled_mutate_rate=0.2)
    neat = NEAT(cfg, seeds=[1, 2, 3, 4])
    g = torch.Generator().manual_seed(5)
    for _ in range(4):
        neat.tell(torch.rand(4, cfg.pop_size, generator=g, dtype=torch.float64) * 16)
    runs = torch.tensor([0, 2]) if subset else None
    R = 2 if subset else 4
    fitness = torch.rand(R, cfg.pop_size, generator=g, dtype=torch.float64) * 16
    species = neat.species if runs is None else neat.species[runs]
    sp = neat.species_state if runs is None else neat.species_state.select_runs(runs)
    rng = RunRNG([1, 3] if subset else [1, 2, 3, 4])
    children, _, sp, info = reproduce(neat.genomes, fitness, species, sp, cfg, rng, 4, fused=True, runs=runs,
                                      in_place=subset)
    bred = info.child_genes
    scanned = breed_kernel.GeneBits(children.conn, children.weight, children.sigma, runs)
    assert int(scanned.count.sum()) > 0
    for name in ("bits", "before", "count", "top", "weight", "sigma"):
        assert torch.equal(getattr(bred, name), getattr(scanned, name)), name
    assert (bred.map is None) == (runs is None) and (runs is None or torch.equal(bred.map, scanned.map))
    out = []
    for genes in (None, bred):
        r2 = RunRNG([1, 3] if subset else [1, 2, 3, 4])
        out.append((*speciate(children, sp, cfg, r2, 5, fused=True, runs=runs, genes=genes), r2.offsets))
    (s0, sp0, o0), (s1, sp1, o1) = out
    assert torch.equal(s0, s1) and torch.equal(o0, o1)
    for name, t in sp0.tensors().items():
        assert torch.equal(t, getattr(sp1, name)), name
    assert bred.nearest is not None  # breeding found the closest representatives ...
    # ... of these representatives only: with one species gone they are found again
    gone = SpeciesState(**{**sp.tensors(), "alive": sp.alive.clone()})
    gone.alive[0, int(torch.nonzero(gone.alive[0])[0])] = False
    out = [speciate(children, gone, cfg, RunRNG([7] * bred.nearest.shape[0]), 5, fused=True, runs=runs, genes=genes)
           for genes in (None, bred)]
    assert torch.equal(out[0][0], out[1][0])
    other = breed_kernel.GeneBits(children.conn[:1], children.weight[:1], children.sigma[:1])
    copy = children.clone()  # the same shapes, other genomes
    for wrong in (other, breed_kernel.GeneBits(copy.conn, copy.weight, copy.sigma, runs)):
        with pytest.raises(ValueError, match="genes describe"):
            speciate(children, sp, cfg, rng, 5, fused=True, runs=runs, genes=wrong)


@needs_kernel
def test_kernel_distances_equal_the_reference():
    cfg = controller_config("snn", node_add_prob=0.3, conn_add_prob=0.5)
    neat = NEAT(cfg, seeds=[0, 1])
    for k in range(6):
        neat.tell(torch.rand(2, cfg.pop_size, generator=torch.Generator().manual_seed(k), dtype=torch.float64))
    g = neat.genomes
    ref = distance(gene_stats(g.conn, g.weight, g.sigma), gene_stats(g.conn, g.weight, g.sigma), cfg)
    bits = breed_kernel.GeneBits(g.conn, g.weight, g.sigma)
    rows = torch.arange(2 * cfg.pop_size).view(2, cfg.pop_size)
    fast = kernel_tests.gene_distances(bits, rows, bits, rows, cfg)
    torch.testing.assert_close(fast, ref, rtol=0, atol=1e-12)
    assert float(ref.std()) > 0.1  # genomes that differ


@needs_kernel
# every norm the larger genome's (min_genes 1), or every norm 1 (50); thresholds that split the genomes
@pytest.mark.parametrize(("min_genes", "threshold"), [(1, 1.0), (1, 2.0), (50, 3.0), (50, 5.0)])
def test_species_kernel_equals_the_reference_with_unequal_coefficients(min_genes, threshold):
    # Many living representatives (the vector path) and unequal excess and disjoint
    # coefficients, so that a swapped or dropped term shows.
    cfg = controller_config("snn", node_add_prob=0.3, conn_add_prob=0.5, compatibility_excess_coefficient=1.3,
                            compatibility_disjoint_coefficient=0.6, compatibility_weight_coefficient=0.45,
                            compatibility_sigma_coefficient=3.0, compatibility_normalize_min_genes=min_genes,
                            compatibility_threshold=threshold)
    neat = NEAT(cfg, seeds=[0, 1])
    for k in range(6):
        neat.tell(torch.rand(2, cfg.pop_size, generator=torch.Generator().manual_seed(k), dtype=torch.float64))
    g, S = neat.genomes, 24
    sp = empty_species(2, cfg.num_nodes, S, device=g.device, dtype=g.weight.dtype)
    reps = torch.arange(0, 6 * S, 6)  # every sixth genome represents a species; some slots dead
    sp.alive[:] = torch.rand(2, S, generator=torch.Generator().manual_seed(9)) < 0.8
    sp.rep_conn[:], sp.rep_weight[:], sp.rep_sigma[:] = g.conn[:, reps], g.weight[:, reps], g.sigma[:, reps]
    out = [speciate(g, sp, cfg, RunRNG([4, 5]), 7, fused=fused) for fused in (False, True)]
    (s0, sp0), (s1, sp1) = out
    assert torch.equal(s0, s1)
    for name, t in sp0.tensors().items():
        assert torch.equal(t, getattr(sp1, name)), name
    kinds = [len(torch.unique(row)) for row in s0]
    assert all(1 < k < cfg.pop_size for k in kinds), kinds  # neither one species nor one each


def _slot0_case():
    # Genome 0 joins the species in slot 0; genomes 1 to 5 match nothing and come later in
    # genome order.
    cfg = small_config(compatibility_threshold=0.5)
    g, _ = population(cfg, seeds=(0,))
    g.weight[0, 1:] = torch.where(g.conn[0, 1:], 8.0, 0.0)  # far from genome 0 in weight
    sp = empty_species(1, cfg.num_nodes, 2, device=g.device, dtype=g.weight.dtype)
    sp.alive[0, 0] = True
    sp.rep_conn[0, 0], sp.rep_weight[0, 0], sp.rep_sigma[0, 0] = g.conn[0, 0], g.weight[0, 0], g.sigma[0, 0]
    return cfg, g, sp


def test_founders_never_take_a_slot_that_has_members():
    # A scatter of flags once let the unassigned genomes' clamped -1 mark slot 0 free, so a
    # new species merged into slot 0.
    cfg, g, sp = _slot0_case()
    for fused in [False] + ([True] if breed_kernel.kernel_available() else []):
        state = SpeciesState(**{k: v.clone() for k, v in sp.tensors().items()})
        species, _ = speciate(g, state, cfg, RunRNG([0]), 1, fused=fused)
        assert species[0, 0] == 0
        assert (species[0, 1:] != 0).all(), fused


def test_the_slot0_check_puts_the_old_rule_back(monkeypatch):
    # experiments.slot0_bug_check is only meaningful if its rule shows the old bug.
    import evolution.speciate as speciate_module
    from experiments.slot0_bug_check import _free_slot_before_the_fix

    monkeypatch.setattr(speciate_module, "_free_slot", _free_slot_before_the_fix)
    cfg, g, sp = _slot0_case()
    species, _ = speciate(g, sp, cfg, RunRNG([0]), 1, fused=False)
    assert species[0, 0] == 0 and (species[0, 1:] == 0).any()


def test_box_muller_is_accurate_and_normal():
    # Against numpy, not torch: torch's log and cos go through MKL VML, whose first call can
    # be inaccurate on one thread (see snn_torch/_vml_warmup.py).
    u = RunRNG([1]).rand(400_000, dtype=torch.float64)[0]
    x = 1.0 - u
    torch.testing.assert_close(_log_unit(x), torch.from_numpy(np.log(x.numpy())), rtol=1e-15, atol=4e-15)
    torch.testing.assert_close(_cos_2pi(u), torch.from_numpy(np.cos(2 * np.pi * u.numpy())), rtol=0, atol=2e-15)
    v = u * 80
    torch.testing.assert_close(_sqrt(v), torch.from_numpy(np.sqrt(v.numpy())), rtol=3e-16, atol=0)
    assert _sqrt(torch.zeros(1, dtype=torch.float64)).item() == 0.0
    z = box_muller(u[::2], u[1::2])
    assert stats.kstest(z.numpy(), "norm").pvalue > 1e-3
    assert stats.shapiro(z[:4000].numpy()).pvalue > 1e-3


@needs_kernel
def test_c_normals_equal_torch_normals_bit_for_bit():
    rng = RunRNG([5, 6])
    z = rng.randn(100_000, dtype=torch.float64)
    for r in range(2):
        out = torch.empty(100_000, dtype=torch.float64)
        kernel_tests.library().normals_check(int(rng.keys[r]) & (2**64 - 1), 0, 100_000, out.data_ptr())
        assert torch.equal(out, z[r])


def test_a_run_draws_the_same_alone_and_in_a_batch():
    batch, alone = RunRNG([4, 9, 2]), RunRNG([9])
    for shape in [(5,), (3, 4), (2,)]:
        assert torch.equal(batch.rand(*shape, dtype=torch.float64)[1], alone.rand(*shape, dtype=torch.float64)[0])
        assert torch.equal(batch.randn(*shape)[1], alone.randn(*shape)[0])
    sub = batch.subset([2, 1])
    assert torch.equal(sub.rand(3)[1], alone.rand(3)[0])  # a subset draws from, and advances, its parent
    assert batch.offsets[1] == alone.offsets[0] and batch.offsets[0] != batch.offsets[1]
    u = batch.rand(100_000)
    assert u.dtype == torch.float32 and 0.0 <= float(u.min()) and float(u.max()) < 1.0


def test_stream_state_round_trips_and_rejects_bad_input():
    rng = RunRNG([1, 2])
    rng.rand(7)
    state = rng.get_state()
    a = rng.randn(4)
    rng.set_state(state)
    assert torch.equal(rng.randn(4), a)
    with pytest.raises(ValueError, match="offsets"):
        rng.set_state(torch.zeros(3, dtype=torch.int64))
    with pytest.raises(ValueError, match="non-negative"):
        rng.set_state(torch.tensor([-1, 0]))
    with pytest.raises(ValueError, match="float32 or float64"):
        rng.rand(2, dtype=torch.float16)


@needs_kernel
def test_kernels_refuse_what_they_cannot_take():
    cfg = small_config(max_hidden=70)  # 74 nodes: more than a 64-bit row of the adjacency
    g, rng = population(cfg, seeds=(0,))
    sp = empty_species(1, cfg.num_nodes, 2, device=g.device, dtype=g.weight.dtype)
    with pytest.raises(ValueError, match="at most 64 nodes"):
        speciate(g, sp, cfg, rng, 0, fused=True)
    species, sp = speciate(g, sp, cfg, rng, 0)  # the default falls back to the tensor operators
    assert (species >= 0).all()
    half, _ = population(small_config(), seeds=(0,))
    half.weight = half.weight.half()
    with pytest.raises(ValueError, match="float32/float64"):
        breed_kernel.GeneBits(half.conn, half.weight, half.sigma)


@needs_kernel
@pytest.mark.parametrize("R,S,N", [(1, 1, 3), (3, 5, 8), (2, 7, 20), (4, 3, 64)])
def test_touched_nodes_equal_the_tensor_reference(R, S, N):
    g = torch.Generator().manual_seed(R * 100 + S * 10 + N)
    conn = torch.rand(R, S, N, N, generator=g) < 0.3 / N  # sparse: some nodes untouched
    alive = torch.rand(R, S, generator=g) < 0.7
    alive[0, 0], conn[0, 0, 0, N - 1] = True, True  # at least one living gene
    expected = ((conn.any(-1) | conn.any(-2)) & alive[..., None]).any(1)
    weight, sigma = conn.float(), torch.ones(R, S)
    for live in (None, alive):  # the dead rows' genes packed, or skipped
        got = breed_kernel.touched_nodes(breed_kernel.GeneBits(conn, weight, sigma, alive=live), alive)
        assert torch.equal(got, expected)
    assert torch.equal(_rep_nodes(SpeciesState(**{**empty_species(R, N, S, device=torch.device("cpu"),
                                                                   dtype=torch.float32).tensors(),
                                                  "alive": alive, "rep_conn": conn})), expected)


@needs_kernel
def test_gene_bits_skip_dead_rows_and_keep_the_living():
    g = torch.Generator().manual_seed(5)
    conn = torch.rand(4, 6, 9, 9, generator=g) < 0.2
    weight, sigma = torch.where(conn, torch.rand(4, 6, 9, 9, generator=g), 0.0), torch.rand(4, 6, generator=g)
    alive = torch.rand(4, 6, generator=g) < 0.5
    full, part = breed_kernel.GeneBits(conn, weight, sigma), breed_kernel.GeneBits(conn, weight, sigma, alive=alive)
    live = alive.flatten()
    for name in ("bits", "before", "count", "top"):
        assert torch.equal(getattr(full, name)[live], getattr(part, name)[live]), name
    assert (part.count[~live] == 0).all() and (part.top[~live] == -1).all() and (part.bits[~live] == 0).all()
    with pytest.raises(ValueError, match="alive has 5 flags for 24 rows"):
        breed_kernel.GeneBits(conn, weight, sigma, alive=torch.ones(5, dtype=torch.bool))


@needs_kernel
def test_kernels_give_the_same_generations_on_one_thread_and_on_two():
    # The kernels share runs out among threads; a run's result must not depend on how.
    cfg = controller_config("snn", node_add_prob=0.2, conn_add_prob=0.3)
    before = torch.get_num_threads()
    out = []
    try:
        for threads in (1, 2):
            torch.set_num_threads(threads)
            neat = NEAT(cfg, seeds=[4, 5, 6])
            g = torch.Generator().manual_seed(2)
            for k in range(8):
                solved = torch.zeros(3, cfg.pop_size, dtype=torch.bool)
                solved[2, 0] = k == 4  # then a subset breeds in place
                neat.tell(torch.rand(3, cfg.pop_size, generator=g, dtype=torch.float64) * 16, solved)
            out.append(neat)
    finally:
        torch.set_num_threads(before)
    _equal_state(*out)
    assert int(out[0].species_state.alive.sum(1).max()) >= 3  # the vector path of the assignment ran


@needs_kernel
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.bool, torch.int64])
def test_put_rows_equals_indexed_assignment_and_refuses_bad_input(dtype):
    g = torch.Generator().manual_seed(3)
    dst = (torch.rand(9, 4, 5, generator=g) * 7).to(dtype)
    src = (torch.rand(3, 4, 5, generator=g) * 7).to(dtype)
    idx = torch.tensor([8, 0, 4])
    expected = dst.clone()
    expected[idx] = src
    breed_kernel.put_rows(dst, idx, src)
    assert torch.equal(dst, expected)
    with pytest.raises(IndexError, match=r"outside \[0, 9\)"):
        breed_kernel.put_rows(dst, torch.tensor([9, 0, 1]), src)
    with pytest.raises(ValueError, match="expected"):
        breed_kernel.put_rows(dst, idx[:2], src)
    with pytest.raises(ValueError, match="contiguous"):
        breed_kernel.put_rows(dst.transpose(1, 2), idx, src.transpose(1, 2))


@needs_kernel
def test_found_species_records_the_new_slots_as_the_tensor_bookkeeping():
    R, S, P = 3, 10, 6
    sp = empty_species(R, 4, S, device=torch.device("cpu"), dtype=torch.float32)
    sp.next_id[:] = torch.tensor([5, 0, 12])
    sp.best_fitness[:] = 1.5
    founded = torch.tensor([[2, 3, 7, 0, 0, 0], [0, 0, 0, 0, 0, 0], [1, 9, 0, 0, 0, 0]])
    n_founded = torch.tensor([3, 0, 2])
    ref = SpeciesState(**{k: v.clone() for k, v in sp.tensors().items()})
    run, k = torch.nonzero(torch.arange(P) < n_founded.unsqueeze(1), as_tuple=True)
    slot = founded[run, k]
    ref.alive[run, slot], ref.best_fitness[run, slot] = True, -torch.inf
    ref.last_improved[run, slot], ref.created[run, slot] = 4, 4
    ref.ident[run, slot] = ref.next_id[run] + k
    ref.next_id += n_founded
    breed_kernel.found_species(founded, n_founded, 4, sp.alive, sp.best_fitness, sp.last_improved, sp.created,
                               sp.ident, sp.next_id)
    for name, t in ref.tensors().items():
        assert torch.equal(t, getattr(sp, name)), name
    before = {k: v.clone() for k, v in sp.tensors().items()}
    with pytest.raises(ValueError, match="beyond the 10 slots"):
        breed_kernel.found_species(torch.tensor([[3, 10, 0, 0, 0, 0]] * 3), n_founded, 5, sp.alive,
                                   sp.best_fitness, sp.last_improved, sp.created, sp.ident, sp.next_id)
    for name, t in before.items():  # refused before anything was written
        assert torch.equal(t, getattr(sp, name)), name
