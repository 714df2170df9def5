"""XOR, the classic NEAT sanity check ([NEAT02] section 4.1): the batched fitness function and the
seeded study Stanley & Miikkulainen (2002) report.

All runs evolve in one batch, each with its own recorded seed. A run is solved at the first
generation where some genome classifies all four patterns (outputs on the right side of
0.5); failures (none within the budget) count as ``generations + 1`` in the mean and median.
"""

from __future__ import annotations

import csv
import io
import json
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import Tensor

from evolution.checkpoint import atomic_write_bytes
from evolution.config import NEATConfig, config_defaults
from evolution.neat import NEAT
from evolution.population import Genomes
from evolution.reporters import TqdmReporter
from snn_torch.modules.recurrent import PopulationRecurrentSigmoid

__all__ = ["XOR_CONFIG", "xor_outputs", "xor_fitness", "xor_solved", "XorSummary", "run_xor", "write_xor_report"]

XOR_INPUTS = torch.tensor([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
XOR_TARGETS = torch.tensor([0.0, 1.0, 1.0, 0.0])

# [NEAT02]'s XOR setting: 2 inputs, a bias, 1 output, feed-forward, population 150.
XOR_CONFIG = NEATConfig(num_inputs=2, num_outputs=1, num_bias=1, feed_forward=True, max_hidden=16,
                        sigma_mutate_rate=0.0, compatibility_sigma_coefficient=0.0)


def xor_outputs(genomes: Genomes, config: NEATConfig) -> Tensor:
    """Network output for the four XOR patterns, ``[R, P, 4]``."""
    R, P, N = genomes.num_runs, genomes.pop_size, genomes.num_nodes
    net = PopulationRecurrentSigmoid(genomes.weight.reshape(-1, N, N), genomes.enabled.reshape(-1, N, N),
                                     num_clamped=config.num_inputs, num_bias=config.num_bias)
    patterns = XOR_INPUTS.to(genomes.device, genomes.weight.dtype)
    # Every genome on every pattern: row g * 4 + k runs genome g on pattern k.
    network = torch.arange(R * P, device=genomes.device).repeat_interleave(4)
    # A feed-forward path is at most (hidden nodes + 1) genes long: that many updates give its output exactly.
    updates = int(genomes.num_hidden(config).max()) + 1
    values = net.control_step(patterns.repeat(R * P, 1), updates=updates, network=network)
    return values[:, config.first_output].view(R, P, 4)


def xor_fitness(genomes: Genomes, config: NEATConfig = XOR_CONFIG) -> Tensor:
    """[NEAT02]: (4 - sum |output - target|)^2, in [0, 16]."""
    err = (xor_outputs(genomes, config) - XOR_TARGETS.to(genomes.device)).abs().sum(-1)
    return (4.0 - err) ** 2


def xor_solved(genomes: Genomes, config: NEATConfig = XOR_CONFIG) -> Tensor:
    """[NEAT02]'s success: all four outputs on the right side of 0.5, ``[R, P]`` bool."""
    out = xor_outputs(genomes, config)
    return ((out > 0.5) == (XOR_TARGETS.to(genomes.device) > 0.5)).all(-1)


NEAT02 = {"mean_generations": 32, "failures": "0/100", "mean_hidden": 2.35}


@dataclass
class XorSummary:
    seeds: list[int]
    solved_generation: list[int]  # -1: not solved
    hidden_nodes: list[int]  # of the solving genome (-1: not solved)
    generations: int
    wall_s: float

    @property
    def failures(self) -> int:
        return sum(g < 0 for g in self.solved_generation)

    def counted(self) -> list[int]:
        return [g if g >= 0 else self.generations + 1 for g in self.solved_generation]

    def table(self) -> dict:
        counted = self.counted()
        solved_hidden = [h for h in self.hidden_nodes if h >= 0]
        return {
            "runs": len(self.seeds),
            "failures": self.failures,
            "mean_generations": statistics.mean(counted),
            "median_generations": statistics.median(counted),
            "best": min(counted),
            "worst": max(counted),
            "mean_hidden_nodes": statistics.mean(solved_hidden) if solved_hidden else float("nan"),
            "wall_s": self.wall_s,
        }


def run_xor(seeds: list[int], *, generations: int = 100, config: NEATConfig = XOR_CONFIG,
            device: str = "cpu", progress: bool = True, out: str | Path | None = None, resume: bool = False,
            checkpoint_every: int | None = None) -> XorSummary:
    """Evolve XOR once per seed, all runs in one batch.

    With ``out``, the run is checkpointed to ``OUT/xor.ckpt`` (``tasks.studies.resumable``):
    every ``checkpoint_every`` generations, by default every 30 s (100 runs' populations take
    about a second to write, and a generation a fraction of that), and at the end; ``resume``
    continues it. The result is the same bits either way."""
    from tasks.studies.resumable import RunCheckpoint, open_run

    start = time.perf_counter()
    checkpoint = None
    neat = NEAT(config, seeds=seeds, device=device) if out is None else None
    if out is not None:
        identity = {"command": "xor", "seeds": list(seeds), "generations": generations, "config": config.to_dict()}
        path = Path(out) / "xor.ckpt"
        neat, data = open_run(path, identity, resume=resume, device=device, defaults={"config": config_defaults()},
                              fresh=lambda: NEAT(config, seeds=seeds, device=device))
        checkpoint = RunCheckpoint(path, identity, generations, every=checkpoint_every,
                                   wall_s=float(data.get("wall_s", 0.0)))
    bar = neat.add_reporter(TqdmReporter(total=generations, initial=neat.generation)) if progress else None
    if checkpoint is not None:
        neat.add_reporter(checkpoint)
    try:
        result = neat.run(lambda g: xor_fitness(g, config), generations - neat.generation,
                          solved_fn=lambda g, f: xor_solved(g, config))
    finally:
        if bar is not None:
            bar.end_run(None)  # closed now: a bar closed at exit would draw over an interruption's message
    hidden = result.best_genomes.num_hidden(config)[:, 0]
    solved = result.solved_generation
    return XorSummary(
        seeds=list(seeds), solved_generation=solved.tolist(),
        hidden_nodes=torch.where(solved >= 0, hidden, -1).tolist(),
        generations=generations, wall_s=checkpoint.wall_s if checkpoint else time.perf_counter() - start,
    )


def write_xor_report(summary: XorSummary, out: str | Path) -> list[Path]:
    """Write ``runs.csv`` (one row per seed), ``summary.json`` and ``summary.md``; ``summary.md``
    last, and removed first, so that its presence marks a complete report."""
    out = Path(out)
    (out / "summary.md").unlink(missing_ok=True)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["seed", "solved_generation", "hidden_nodes"])
    w.writerows(zip(summary.seeds, summary.solved_generation, summary.hidden_nodes, strict=True))
    t = summary.table()
    md = ("| | runs | failures | mean gens | median gens | best | worst | mean hidden nodes |\n"
          "|---|---|---|---|---|---|---|---|\n"
          f"| snn-neat | {t['runs']} | {t['failures']} | {t['mean_generations']:.2f} | {t['median_generations']:.1f} "
          f"| {t['best']} | {t['worst']} | {t['mean_hidden_nodes']:.2f} |\n"
          f"| NEAT (2002) | 100 | 0 | 32 | - | - | - | 2.35 |\n")
    return [atomic_write_bytes(out / "runs.csv", buf.getvalue().encode()),
            atomic_write_bytes(out / "summary.json", json.dumps(t, indent=1).encode()),
            atomic_write_bytes(out / "summary.md", md.encode())]
