"""Are Table I's NEAT-SNN champions robust to their input noise, or were they lucky?

    python -m tasks.experiments.markov_noise_retest results/table1/champions --streams 10

The Markov task's input spikes are random, drawn from a stream keyed by the genome, so each
network is evaluated once on one realisation of its spike trains (as the paper evaluates
each network once). A champion "solves" the task when it balances the pole for 100,000
steps on that realisation. This re-runs every NEAT-SNN champion from the same start on
``--streams`` fresh noise streams and reports how often it holds the pole for 100,000 steps
again, and the median steps it lasts.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics

import torch
from torch import Tensor

from evolution.genome_io import load_genome
from evolution.population import Genomes
from tasks.cartpole import DEFAULT_PLANT
from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec, closed_loop
from tasks.experiments.cartpole import MARKOV, markov_config, markov_start

__all__ = ["retest_steps"]


def retest_steps(champions: Genomes, streams: int, *, max_steps: int = MARKOV["max_steps"],
                 spec: MarkovSpikingSpec | None = None) -> Tensor:
    """Steps balanced ``[G, streams]`` by each of ``G`` Table I NEAT-SNN champions
    (``[G, 1]`` genomes) on noise streams 1..``streams`` (stream 0 is the one evolution saw)."""
    if streams < 1:
        raise ValueError(f"streams must be >= 1, got {streams}")
    cfg = markov_config("snn")
    spec = MarkovSpikingSpec() if spec is None else spec
    G = champions.num_runs
    flat = Genomes(**{k: v.reshape(1, G, *v.shape[2:]) for k, v in champions.tensors().items()})
    out = []
    for k in range(1, streams + 1):
        policy = MarkovSpikingPolicy(flat, cfg, spec, MARKOV["tau_s"], DEFAULT_PLANT, noise_seed=k)
        steps, _ = closed_loop(policy, markov_start(G, dtype=flat.weight.dtype), tau_s=MARKOV["tau_s"],
                               max_steps=max_steps)
        out.append(steps)
    return torch.stack(out, 1)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("champions", help="folder of champion genomes (snn_seed*.json) from `snn-neat reproduce table1`")
    ap.add_argument("--streams", type=int, default=10, help="fresh noise streams per champion (default 10)")
    args = ap.parse_args(argv)
    paths = sorted(glob.glob(os.path.join(args.champions, "snn_seed*.json")),
                   key=lambda p: int(p.rsplit("seed", 1)[1].split(".")[0]))
    if not paths:
        raise SystemExit(f"markov_noise_retest: no snn_seed*.json in {args.champions}")
    cfg = markov_config("snn")
    genomes = [load_genome(p, cfg) for p in paths]
    champions = Genomes(**{k: torch.cat([getattr(g, k) for g in genomes]) for k in genomes[0].tensors()})
    steps = retest_steps(champions, args.streams)
    held = (steps >= MARKOV["max_steps"]).double().mean(1)
    print(f"{len(paths)} NEAT-SNN champions x {args.streams} fresh noise streams, {MARKOV['max_steps']} steps each")
    print(f"fraction of streams held, per champion: mean {held.mean():.3f}, median {held.median():.3f}, "
          f"min {held.min():.3f}, max {held.max():.3f}")
    print(f"champions that hold every stream: {int((held == 1).sum())}/{len(paths)}; "
          f"that hold none: {int((held == 0).sum())}/{len(paths)}")
    print(f"median steps over all episodes: {statistics.median(steps.flatten().tolist()):.0f}")


if __name__ == "__main__":
    main()
