"""Time one whole NEAT reproduction step (stagnation, allocation, selection, crossover,
mutation, speciation) for R x P genomes, beside neat-python's when it is installed.

    python benchmarks/reproduction_step.py            # R x P in {150, 9000, 100000}
    python benchmarks/reproduction_step.py --quick    # 150 and 9000 only
    python benchmarks/reproduction_step.py --generation-share   # GA share of real generations

Populations are runs of 150 genomes (the paper's size) in the XOR layout (2 inputs, a bias,
1 output, ``--max-hidden`` hidden slots), first grown for ``--warmup`` generations with
random fitness so genomes carry hidden nodes and many species exist. neat-python
(``pip install -e ".[bench]"``) runs its ``DefaultReproduction.reproduce`` plus
``DefaultSpeciesSet.speciate`` on one population of the same total size, same rates.
Medians of ``--repeats`` steps; one thread unless ``--threads`` says otherwise. The same
step by the tensor operators (``NEAT.fused_breeding = False``, the reference and CUDA path)
is timed beside the C kernels up to 9000 genomes.

``--generation-share`` times real generations instead: Table II's task (non-Markov cart-pole,
the tuned GA settings of each controller), 60 runs of 150 genomes, evaluation (the C closed
loop) against breeding (``NEAT.tell``), generation by generation, for
``--share-generations`` generations.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution.neat import NEAT
from tasks.studies.xor import XOR_CONFIG


def _fitness(neat: NEAT, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.rand(neat.num_runs, neat.config.pop_size, generator=g, dtype=torch.float64) * 16


def time_snn_neat(total: int, max_hidden: int, warmup: int, repeats: int,
                  fused: bool | None = None) -> tuple[float, float, float]:
    """Median seconds per reproduction step, mean hidden nodes per genome, mean living
    species per run. ``fused=False``: the tensor operators instead of the C kernels."""
    import dataclasses

    cfg = dataclasses.replace(XOR_CONFIG, max_hidden=max_hidden, node_add_prob=0.2, conn_add_prob=0.3)
    runs = max(1, total // cfg.pop_size)
    neat = NEAT(cfg, seeds=range(runs))
    neat.fused_breeding = fused
    for k in range(warmup):
        neat.tell(_fitness(neat, k))
    times = []
    for k in range(repeats):
        f = _fitness(neat, 1000 + k)
        start = time.perf_counter()
        neat.tell(f)
        times.append(time.perf_counter() - start)
    return (statistics.median(times), neat.genomes.num_hidden(cfg).double().mean().item(),
            neat.species_state.alive.sum(1).double().mean().item())


def time_neat_python(total: int, warmup: int, repeats: int) -> float | None:
    try:
        import neat
    except ImportError:
        return None
    import os
    import random
    import tempfile

    ini = f"""
[NEAT]
fitness_criterion = max
fitness_threshold = 1e9
pop_size = {total}
reset_on_extinction = True
no_fitness_termination = True
[DefaultGenome]
num_inputs = 2
num_hidden = 0
num_outputs = 1
initial_connection = full_direct
feed_forward = True
compatibility_disjoint_coefficient = 1.0
compatibility_weight_coefficient = 0.4
conn_add_prob = 0.3
conn_delete_prob = 0.0
node_add_prob = 0.2
node_delete_prob = 0.0
activation_default = sigmoid
activation_options = sigmoid
activation_mutate_rate = 0.0
aggregation_default = sum
aggregation_options = sum
aggregation_mutate_rate = 0.0
bias_init_mean = 0.0
bias_init_stdev = 1.0
bias_replace_rate = 0.1
bias_mutate_rate = 0.8
bias_mutate_power = 2.5
bias_max_value = 8.0
bias_min_value = -8.0
response_init_mean = 1.0
response_init_stdev = 0.0
response_replace_rate = 0.0
response_mutate_rate = 0.0
response_mutate_power = 0.0
response_max_value = 30.0
response_min_value = -30.0
weight_max_value = 8
weight_min_value = -8
weight_init_mean = 0.0
weight_init_stdev = 1.0
weight_mutate_rate = 0.8
weight_replace_rate = 0.1
weight_mutate_power = 2.5
enabled_default = True
enabled_mutate_rate = 0.01
single_structural_mutation = False
[DefaultSpeciesSet]
compatibility_threshold = 3.0
[DefaultStagnation]
species_fitness_func = max
max_stagnation = 15
species_elitism = 2
[DefaultReproduction]
elitism = 1
survival_threshold = 0.2
"""
    with tempfile.NamedTemporaryFile("w", suffix=".ini", delete=False) as fh:
        fh.write(ini)
    try:
        cfg = neat.Config(neat.DefaultGenome, neat.DefaultReproduction, neat.DefaultSpeciesSet,
                          neat.DefaultStagnation, fh.name)
    finally:
        os.unlink(fh.name)
    random.seed(0)
    pop = neat.Population(cfg)
    times = []
    for k in range(warmup + repeats):
        for g in pop.population.values():
            g.fitness = random.random() * 16
        start = time.perf_counter()
        pop.population = pop.reproduction.reproduce(cfg, pop.species, cfg.pop_size, pop.generation)
        pop.species.speciate(cfg, pop.population, pop.generation)
        pop.generation += 1
        if k >= warmup:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def generation_share(controller: str, generations: int) -> None:
    """Per generation: evaluation seconds, breeding seconds and breeding's share, Table II's task."""
    from tasks.studies.registry import STUDIES, describe_ga

    preset, extra = STUDIES["table2"].ga_choice(controller)
    cfg = STUDIES["table2"].config(controller)
    neat = NEAT(cfg, seeds=range(60))
    fitness_fn = STUDIES["table2"].fitness(controller, cfg)
    print(f"{controller}: Table II task, 60 runs x {cfg.pop_size}, GA {describe_ga(preset, extra)}")
    print(f"{'gen':>4} {'runs left':>9} {'evaluate s':>11} {'breed s':>8} {'us/genome':>10} {'breed share':>12}")
    shares, per_genome = [], []
    for gen in range(generations):
        if not bool(neat.active_runs.any()):
            break
        left = int(neat.active_runs.sum())
        t0 = time.perf_counter()
        fitness = neat.evaluate_active(fitness_fn, neat.ask())
        t1 = time.perf_counter()
        neat.tell(fitness)
        t2 = time.perf_counter()
        shares.append((t2 - t1) / (t2 - t0))
        per_genome.append(1e6 * (t2 - t1) / (left * cfg.pop_size))
        print(f"{gen:>4} {left:>9} {t1 - t0:>11.3f} {t2 - t1:>8.3f} {per_genome[-1]:>10.2f} {100 * shares[-1]:>11.0f}%",
              flush=True)
    print(f"median breed share {100 * statistics.median(shares):.0f}%, median {statistics.median(per_genome):.2f} "
          f"us per evolving genome (issue 8 targets: under 5%, under 1 us)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--max-hidden", type=int, default=16)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--no-neat-python", action="store_true", help="skip neat-python even when installed")
    ap.add_argument("--generation-share", action="store_true",
                    help="time evaluation against breeding in real generations of Table II's task")
    ap.add_argument("--share-generations", type=int, default=8)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    if args.generation_share:
        for controller in ("snn", "sigmoid"):
            generation_share(controller, args.share_generations)
        return
    sizes = [150, 9000] if args.quick else [150, 9000, 100000]
    print(f"torch {torch.__version__}, {args.threads} thread(s), XOR layout with {args.max_hidden} hidden slots")
    print("snn-neat: C kernels (the default on CPU); tensor ops: the same step by the tensor operators")
    print(f"{'R x P':>8} {'snn-neat s/step':>16} {'us/genome':>10} {'hidden':>7} {'species':>8} "
          f"{'tensor ops us/genome':>21} {'neat-python s/step':>19} {'us/genome':>10} {'speed-up':>9}")
    for total in sizes:
        t, hidden, species = time_snn_neat(total, args.max_hidden, args.warmup, args.repeats)
        t_ref = None if total > 9000 else time_snn_neat(total, args.max_hidden, args.warmup, args.repeats, False)[0]
        ref_col = f"{1e6 * t_ref / total:>21.1f}" if t_ref is not None else f"{'-':>21}"
        t_np = None if args.no_neat_python or total > 9000 else time_neat_python(total, args.warmup, args.repeats)
        np_cols = (f"{t_np:>19.4f} {1e6 * t_np / total:>10.1f} {t_np / t:>8.1f}x" if t_np is not None
                   else f"{'-':>19} {'-':>10} {'-':>9}")
        print(f"{total:>8} {t:>16.4f} {1e6 * t / total:>10.2f} {hidden:>7.2f} {species:>8.1f} {ref_col} {np_cols}",
              flush=True)
    print("target (issue 8): under 1 us per genome at 9000, and under 5% of a generation (--generation-share)")


if __name__ == "__main__":
    main()
