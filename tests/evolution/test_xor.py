"""NEAT's classic sanity check: sigmoid tensor NEAT solves XOR.

The full 100-run figures (seeds 0-99) are in docs/neat.md (`snn-neat xor --runs 100`). Here a
smaller seeded sample must stay within loose bounds that a working NEAT meets easily and
a broken one (no speciation, no structural growth, wrong crossover) does not: on seeds
100-123 at most 6 of 24 runs may fail within 100 generations (the 100-run failure rate is
12 %; P(>= 7 of 24 | 12 %) < 2 %), the median must be at most 70 generations, and every
solution must use a hidden node (XOR is not linearly separable).
"""

import statistics

import torch

from tasks.studies.xor import XOR_CONFIG, run_xor, xor_outputs


def test_sigmoid_neat_solves_xor_on_a_seeded_sample():
    torch.set_num_threads(1)
    summary = run_xor(list(range(100, 124)), generations=100, progress=False)
    assert summary.failures <= 6, summary.solved_generation
    assert statistics.median(summary.counted()) <= 70, summary.solved_generation
    solved_hidden = [h for h, g in zip(summary.hidden_nodes, summary.solved_generation, strict=True) if g >= 0]
    assert min(solved_hidden) >= 1


def test_solution_genomes_really_solve_xor():
    from evolution.neat import NEAT
    from tasks.studies.xor import xor_fitness, xor_solved

    neat = NEAT(XOR_CONFIG, seeds=[3, 4])
    result = neat.run(xor_fitness, 100, solved_fn=lambda g, f: xor_solved(g))
    for r in range(2):
        if result.solved_generation[r] > 0:
            out = xor_outputs(result.best_genomes.select_runs([r]), XOR_CONFIG)[0, 0]
            assert ((out > 0.5) == torch.tensor([False, True, True, False])).all()
