"""Which of NEAT C++ 1.2.1's mechanisms, and which input coding, buys how much (issue 29, item 5).

    python -m experiments.neat121_ablation dpv --controller sigmoid --seeds 300-349

Runs the double-pole study (``tasks.studies.registry.STUDIES``) with NEAT C++ 1.2.1's preset
(``--ga neat-1.2.1-VARIANT``) and its signed coding, then the same with one mechanism switched
back to this NEAT's default at a time, the study's own coding, and the study's tuned GA. One
line per setting: runs solved, and evaluations to solve as NEAT 1.2.1 counts them (mean and
median over the solved runs), with the Mann-Whitney p-value against the full preset (failures
counted as the budget + 1 generations). One thread; seeds recorded in the output.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import torch

from evolution.neat import NEAT
from experiments.sensitivity import seed_range
from tasks.studies.double_pole_report import neat121_counts
from tasks.studies.registry import STUDIES, StudyOptions
from tasks.studies.results import mann_whitney

__all__ = ["ABLATIONS", "run_setting"]

# name -> (NEATConfig overrides on top of the preset, coding, GA)
ABLATIONS: dict[str, tuple[dict, str, str]] = {
    "NEAT 1.2.1 preset, signed coding": ({}, "signed", "neat-1.2.1"),
    "- stagnant species removed, not penalised x0.01": ({"stagnant_fitness_factor": 0.0}, "signed", "neat-1.2.1"),
    "- no obliteration of the oldest worst species": ({"obliterate_interval": 0}, "signed", "neat-1.2.1"),
    "- no delta coding (population stagnation)": ({"population_stagnation": 0}, "signed", "neat-1.2.1"),
    "- mutations not exclusive": ({"mutation_exclusive": False}, "signed", "neat-1.2.1"),
    "- crossover children always mutated": ({"mate_only_prob": 0.0}, "signed", "neat-1.2.1"),
    "- Gaussian weight perturbation (ours)": ({"weight_mutate_neatc": False}, "signed", "neat-1.2.1"),
    "- no averaging crossover": ({"crossover_average_prob": 0.0}, "signed", "neat-1.2.1"),
    "- distance divided by gene count (N >= 20)": ({"compatibility_normalize_min_genes": 20}, "signed", "neat-1.2.1"),
    "- new links among all free slots, not by 20 tries": ({"conn_add_tries": 0}, "signed", "neat-1.2.1"),
    "- Gaussian initial weights, stdev 1 (ours)": ({"weight_init_uniform": False, "weight_init_stdev": 1.0}, "signed",
                                                    "neat-1.2.1"),
    "- each new link its own weight (no innovation list)": ({"conn_add_shared_weight": False}, "signed", "neat-1.2.1"),
    "- ceil(s * size) parents per species (ours)": ({"survival_neatc": False}, "signed", "neat-1.2.1"),
    "- stagnation clock restarted before the penalty (ours)": ({"stagnation_clock_before": False}, "signed",
                                                               "neat-1.2.1"),
    "- the distance reads the weights, not mutation_num (ours)": ({"compat_mutation_num": False}, "signed",
                                                                  "neat-1.2.1"),
    "- any enabled gene split, bias genes too (ours)": ({"node_add_neatc": False}, "signed", "neat-1.2.1"),
    "- bias input 1, not 0.5 (ours)": ({"bias_value": 1.0}, "signed", "neat-1.2.1"),
    "+ first fit against champions (NEAT 1.2.1's speciation)": ({"speciate_neatc": True}, "signed", "neat-1.2.1"),
    "- the study's coding ([0, 1] over its bounds)": ({}, "study", "neat-1.2.1"),
    "the study's tuned GA, signed coding": ({}, "signed", "tuned"),
}


def run_setting(variant: str, controller: str, seeds: list[int], generations: int, overrides: dict, coding: str,
                ga: str) -> dict:
    """One setting's runs: solved generation and NEAT 1.2.1's evaluation count per run."""
    study = STUDIES[variant]
    ga = f"neat-1.2.1-{variant}" if ga == "neat-1.2.1" else ga
    # the study's own fitness and test of a solution, with NEAT 1.2.1's test of a generation on DPNV
    options = StudyOptions(setup="neat-2002", ga=ga, coding=coding,
                           champion_test="species" if variant == "dpnv" else None)
    config = study.config(controller, options, **overrides)
    neat = NEAT(config, seeds=seeds)
    start = time.process_time()
    neat.run(study.fitness(controller, config, options), generations,
             solved_fn=study.solved(controller, config, options, neat=neat))
    P = config.pop_size
    evals = neat121_counts(P, neat.solved_generation.tolist(), neat.solved_position.tolist())
    return {"solved": sum(e is not None for e in evals), "runs": len(seeds), "evaluations": evals,
            "counted": [e if e is not None else P * (generations + 1) for e in evals],
            "cpu_s": round(time.process_time() - start, 1)}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("variant", choices=("dpv", "dpnv"))
    p.add_argument("--controller", choices=("snn", "sigmoid"), default="sigmoid")
    p.add_argument("--seeds", type=seed_range, default=seed_range("300-349"))
    p.add_argument("--generations", type=int, default=100)
    p.add_argument("--only", nargs="*", default=None, help="settings to run (substrings of their names)")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    full = None
    for name, (overrides, coding, ga) in ABLATIONS.items():
        if a.only and not any(o in name for o in a.only):
            continue
        r = run_setting(a.variant, a.controller, a.seeds, a.generations, overrides, coding, ga)
        solved = [e for e in r["evaluations"] if e is not None]
        full = r if full is None else full
        p_value = mann_whitney(r["counted"], full["counted"])["p_value"] if r is not full else float("nan")
        print(json.dumps({"setting": name, "variant": a.variant, "controller": a.controller,
                          "seeds": f"{a.seeds[0]}-{a.seeds[-1]}", "solved": f"{r['solved']}/{r['runs']}",
                          "mean": round(statistics.mean(solved)) if solved else None,
                          "median": statistics.median(solved) if solved else None,
                          "p_vs_preset": p_value, "cpu_s": r["cpu_s"]}), flush=True)


if __name__ == "__main__":
    main()
