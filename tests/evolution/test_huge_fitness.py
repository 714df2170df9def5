"""Any finite fitness breeds: per-species sums of huge values must not overflow into a crash."""

import pytest
import torch

from evolution.kernels import select as select_kernel
from evolution.neat import NEAT
from evolution.population import check_invariants
from evolution.reproduce import allocate_offspring
from tests.evolution.helpers import small_config

CFG = small_config(pop_size=40, max_hidden=6, node_add_prob=0.2, conn_add_prob=0.3)
PATHS = [False] + ([True] if select_kernel.kernel_available() else [])


def _evolve(fused: bool, low: float, high: float, generations: int = 3, device: str = "cpu") -> NEAT:
    gen = torch.Generator().manual_seed(3)
    neat = NEAT(CFG, seeds=[0, 1], device=device)
    neat.fused_breeding = fused
    for _ in range(generations):
        u = torch.rand(2, CFG.pop_size, generator=gen, dtype=torch.float64)
        neat.tell((low * (1 - u) + high * u).to(device))
    return neat


def test_huge_finite_fitness_breeds_on_cuda():
    neat = _evolve(False, -1.7e308, 1.7e308, device="cuda")  # the tensor path on the GPU
    assert neat.generation == 3
    check_invariants(neat.genomes, CFG)


@pytest.mark.parametrize("low, high", [(0.0, 1.7e307), (-1.7e308, 1.7e308), (1e308, 1.79e308)])
def test_huge_finite_fitness_breeds_the_same_on_both_paths(low, high):
    # Before: the C kernels segfaulted, the tensor path raised an IndexError.
    runs = [_evolve(fused, low, high) for fused in PATHS]
    for neat in runs:
        assert neat.generation == 3 and neat.genomes.weight.shape[1] == CFG.pop_size
        check_invariants(neat.genomes, CFG)
    for name, t in runs[0].genomes.tensors().items():
        assert torch.equal(getattr(runs[-1].genomes, name), t), name


def _counts(fitness, species, survivors, fused):
    if not fused:
        return allocate_offspring(fitness, species, survivors, fitness.shape[1])
    R, S = survivors.shape
    return select_kernel.species_offspring(
        fitness, species, survivors, torch.full((R, S), -torch.inf, dtype=torch.float64),
        torch.zeros(R, S, dtype=torch.long), CFG, 1)[3]


@pytest.mark.parametrize("fused", PATHS)
def test_offspring_of_huge_fitness_are_those_of_the_same_fitness_scaled_down(fused):
    gen = torch.Generator().manual_seed(0)
    P, S = 150, 5
    fitness = torch.rand(3, P, generator=gen, dtype=torch.float64) * 4 - 1
    species = torch.randint(0, S, (3, P), generator=gen)
    survivors = torch.ones(3, S, dtype=torch.bool)
    counts = _counts(fitness, species, survivors, fused)
    huge = _counts(fitness * 2.0**1020, species, survivors, fused)  # sums of 150 overflow a double
    assert torch.equal(huge, counts)
    assert torch.equal(huge.sum(1), torch.full((3,), P))


@pytest.mark.skipif(not select_kernel.kernel_available(), reason="no C compiler")
def test_selection_kernel_refuses_counts_it_would_index_out_of_bounds_with():
    from evolution.rng import RunRNG

    P, S = 10, 2
    fitness, species = torch.zeros(1, P, dtype=torch.float64), torch.zeros(1, P, dtype=torch.long)
    survivors = torch.ones(1, S, dtype=torch.bool)
    for bad in ([P + 5, 0], [-3, P + 3]):
        with pytest.raises(ValueError, match="sum to 10"):
            select_kernel.select_parents(fitness, species, survivors, torch.tensor([bad]), CFG, RunRNG([0]))


def test_statistics_of_huge_fitness_stay_finite_and_right(capsys):
    import math

    from evolution.reporters import StatisticsReporter, StdOutReporter

    P = CFG.pop_size
    neat = NEAT(CFG, seeds=[0])
    stats = neat.add_reporter(StatisticsReporter())
    neat.add_reporter(StdOutReporter())
    f = torch.full((1, P), 1.5e308, dtype=torch.float64)
    f[0, 0] = -1.5e308
    neat.tell(f)
    row = stats.rows[0]
    assert math.isclose(row["mean_fitness"], 1.5e308 / P * (P - 2), rel_tol=1e-12)  # before: inf
    assert math.isclose(row["std_fitness"], 1.5e308 / P * 2 * math.sqrt(P - 1), rel_tol=1e-12)
    assert "inf" not in capsys.readouterr().out
