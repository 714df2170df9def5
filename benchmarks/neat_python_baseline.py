"""Is our sigmoid NEAT baseline at least as strong as neat-python's on the paper's tasks?

    python benchmarks/neat_python_baseline.py --task markov --seeds 0-11
    python benchmarks/neat_python_baseline.py --task nonmarkov --seeds 0-29 [--self-loops]

Runs neat-python 2.0.0 (``pip install -e ".[bench]"``) on the same cart-pole as
``snn-neat reproduce`` (same plant, explicit Euler, failure limits, start at theta = 3
degrees, inputs normalised to [0, 1] over the same bounds) with the paper's settings where
it gives them (population 150, add node 0.03, add connection 0.1, survival threshold 0.2, at
most 100 generations) and neat-python's defaults elsewhere, a recurrent network activated
once per control step: Table I (``markov``): the four state variables, F = +10 N when the
output exceeds 0.5, else -10 N, tau 20 ms, success at 100,000 steps; Table II
(``nonmarkov``): x and theta, F = 10 (2 y - 1), tau 10 ms, success at 5000 steps.

Start genome as the paper's: inputs wired to the output. neat-python's ``full_direct``
start for recurrent genomes also adds a self-connection to every node, which is removed
here unless ``--self-loops``. Prints the generation each seed solved at and the summary
(failures counted as 101 generations), to compare with ``runs.csv`` of a reproduction.
neat-python evaluates in pure Python, so Table I costs seconds per solving genome.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time

from compare_neat_python import plant_step  # the plant in Python floats (same folder)


def seed_range(text: str) -> list[int]:
    """``"0-59"`` -> [0, ..., 59]; ``"7"`` -> [7]."""
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


TASKS = {
    # observed state indices, normalisation bounds, tau (s), success steps, bang-bang
    "markov": ((0, 1, 2, 3), (2.4, 1.5, math.radians(12.0), 2.0), 0.02, 100_000, True),
    "nonmarkov": ((0, 2), (2.4, math.radians(12.0)), 0.01, 5000, False),
}


def _config_text(num_inputs: int, threshold: int, elitism: int = 2) -> str:
    return f"""
[NEAT]
fitness_criterion = max
fitness_threshold = {threshold}
pop_size = 150
reset_on_extinction = True
no_fitness_termination = False
[PaperStartGenome]
num_inputs = {num_inputs}
num_hidden = 0
num_outputs = 1
initial_connection = full_direct
feed_forward = False
compatibility_disjoint_coefficient = 1.0
compatibility_weight_coefficient = 0.5
conn_add_prob = 0.1
conn_delete_prob = 0.0
node_add_prob = 0.03
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
bias_mutate_rate = 0.7
bias_mutate_power = 0.5
bias_max_value = 30.0
bias_min_value = -30.0
response_init_mean = 1.0
response_init_stdev = 0.0
response_replace_rate = 0.0
response_mutate_rate = 0.0
response_mutate_power = 0.0
response_max_value = 30.0
response_min_value = -30.0
weight_max_value = 30
weight_min_value = -30
weight_init_mean = 0.0
weight_init_stdev = 1.0
weight_mutate_rate = 0.8
weight_replace_rate = 0.1
weight_mutate_power = 0.5
enabled_default = True
enabled_mutate_rate = 0.01
[DefaultSpeciesSet]
compatibility_threshold = 3.0
[DefaultStagnation]
species_fitness_func = max
max_stagnation = 20
species_elitism = 2
[DefaultReproduction]
elitism = {elitism}
survival_threshold = 0.2
"""


def episode(net, task: str) -> int:
    """Control steps balanced from theta = 3 degrees."""
    obs, lim, tau, max_steps, bang = TASKS[task]
    s = [0.0, 0.0, math.radians(3.0), 0.0]
    for t in range(max_steps):
        y = net.activate([min(max((s[k] / b + 1.0) * 0.5, 0.0), 1.0) for k, b in zip(obs, lim, strict=True)])[0]
        force = (10.0 if y > 0.5 else -10.0) if bang else 10.0 * (2.0 * y - 1.0)
        s = plant_step(s, force, tau)
        if abs(s[0]) > 2.4 or abs(s[2]) > math.radians(12.0):
            return t
    return max_steps


def run_seed(task: str, seed: int, generations: int, self_loops: bool, elitism: int = 2) -> int:
    """The generation (1 = the initial population) at which ``seed`` solved, or -1."""
    import neat

    class PaperStartGenome(neat.DefaultGenome):
        def configure_new(self, config):
            super().configure_new(config)
            if not self_loops:
                for key in [k for k in self.connections if k[0] == k[1]]:
                    del self.connections[key]

    obs, _, _, max_steps, _ = TASKS[task]
    with tempfile.NamedTemporaryFile("w", suffix=".ini", delete=False) as f:
        f.write(_config_text(len(obs), max_steps, elitism))
    try:
        config = neat.Config(PaperStartGenome, neat.DefaultReproduction, neat.DefaultSpeciesSet,
                             neat.DefaultStagnation, f.name)
    finally:
        os.unlink(f.name)
    pop = neat.Population(config, seed=seed)
    state = {"generation": 0, "solved": -1}

    def evaluate(genomes, cfg):
        state["generation"] += 1
        for _, genome in genomes:
            genome.fitness = float(episode(neat.nn.RecurrentNetwork.create(genome, cfg), task))
            if genome.fitness >= max_steps and state["solved"] < 0:
                state["solved"] = state["generation"]

    try:
        pop.run(evaluate, generations)
    except neat.CompleteExtinctionException:
        pass
    return state["solved"]


def compare(neat_python: list[int], runs_csv: list[str]) -> None:
    """Our sigmoid NEAT's runs (from ``runs.csv`` files) against neat-python's, U-tested."""
    import csv

    from tasks.studies.results import mann_whitney

    ours = []
    for path in runs_csv:
        with open(path, newline="") as f:
            ours += [int(r["counted_generations"]) for r in csv.DictReader(f) if r["controller"] == "sigmoid"]
    if not ours:
        raise SystemExit(f"--compare: no sigmoid runs in {runs_csv}")
    p = mann_whitney(ours, neat_python)["p_value"]
    faster = "ours" if statistics.mean(ours) < statistics.mean(neat_python) else "neat-python"
    print(f"snn-neat sigmoid NEAT ({len(ours)} runs): median {statistics.median(ours):g}, mean "
          f"{statistics.mean(ours):.2f}; neat-python ({len(neat_python)} runs): median "
          f"{statistics.median(neat_python):g}, mean {statistics.mean(neat_python):.2f}; Mann-Whitney U p = {p:.3g} "
          f"(lower mean: {faster})")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", choices=sorted(TASKS), default="markov")
    ap.add_argument("--seeds", type=seed_range, default=seed_range("0-11"), help="e.g. 0-29 (default 0-11)")
    ap.add_argument("--generations", type=int, default=100)
    ap.add_argument("--self-loops", action="store_true", help="keep neat-python's self-connections at the start")
    ap.add_argument("--elitism", type=int, default=2,
                    help="neat-python's per-species elitism (default 2, its own; 1 is closer to the paper's)")
    ap.add_argument("--compare", nargs="*", default=[], metavar="RUNS_CSV",
                    help="runs.csv files of `snn-neat reproduce`: print their sigmoid NEAT runs against "
                         "neat-python's (medians, means, Mann-Whitney U)")
    args = ap.parse_args(argv)
    solved = []
    for seed in args.seeds:
        start = time.perf_counter()
        g = run_seed(args.task, seed, args.generations, args.self_loops, args.elitism)
        solved.append(g)
        print(f"seed {seed}: " + (f"solved at generation {g}" if g > 0 else "not solved")
              + f" ({time.perf_counter() - start:.0f} s)", flush=True)
    counted = [g if g > 0 else args.generations + 1 for g in solved]
    fails = sum(g < 0 for g in solved)
    if args.compare:
        compare(counted, args.compare)
    print(f"neat-python 2.0.0, {args.task}{' (self-loop start)' if args.self_loops else ''}, elitism {args.elitism}, seeds "
          f"{args.seeds[0]}-{args.seeds[-1]}: failures {fails}/{len(solved)}, median {statistics.median(counted):g}, "
          f"mean {statistics.mean(counted):.2f} generations (failures as {args.generations + 1})")


if __name__ == "__main__":
    main()
