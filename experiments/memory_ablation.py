"""Does a NEAT-SNN champion use memory? Run it with its state carried, wiped, or settled.

    python -m experiments.memory_ablation results/table2/champions

Three ways to run each champion from the paper's start (theta = 3 degrees) for 5000 steps:

- ``as evolved``: the network state (v, u, last spikes, the rate window) carries across
  control steps;
- ``state wiped``: every control step starts from the rest state with an empty window;
- ``static map``: every control step the network starts from rest, settles for
  ``settle_ms`` on the current input, and its rates over the next window give the force, a
  memoryless function of (x, theta) that keeps the network's steady-state response.

A champion that holds the pole only as evolved relies on state carried between steps,
which is where the velocities it is never given must come from.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics

import torch
from torch import Tensor

from evolution.genome_io import load_genome
from evolution.phenotype import SpikingController, SpikingSpec, SpikingState
from evolution.population import Genomes
from evolution.rollout import rollout
from snn_torch.modules.coding import RateWindow, RateWindowState
from tasks.cartpole import CartPoleTask
from tasks.studies.cartpole import NONMARKOV, controller_config

__all__ = ["WipedStateController", "StaticMapController", "ablation_steps"]


def _rest(self: SpikingController, state: SpikingState) -> SpikingState:
    v = state.neurons.v
    window = RateWindowState(torch.zeros_like(state.window.history), 0)
    return state._replace(neurons=self.network.initial_state(v), window=window)


class WipedStateController(SpikingController):
    """The champion with its network state and rate window reset before every control step."""

    def act(self, obs01: Tensor, state: SpikingState):
        return super().act(obs01, _rest(self, state))


class StaticMapController(SpikingController):
    """A memoryless map of (x, theta): from rest, settle ``settle_ms``, then decode the rates of
    one window of ``rate_window_steps`` control steps."""

    settle_ms: float = 160.0

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        W = self.spec.rate_window_steps
        self.window = RateWindow(1, W * self.window.period_s)  # the whole window measured as one step
        self.settle_substeps, self.window_substeps = int(round(self.settle_ms / self.spec.dt_ms)), W * self.substeps

    def act(self, obs01: Tensor, state: SpikingState):
        fresh = _rest(self, state)
        try:
            self.substeps = self.settle_substeps
            _, settled, _ = super().act(obs01, fresh)
            self.substeps = self.window_substeps
            action, _, counts = super().act(obs01, fresh._replace(neurons=settled.neurons))
        finally:
            self.substeps = self.window_substeps // self.spec.rate_window_steps
        return action, state, counts


def ablation_steps(genomes: Genomes, *, max_steps: int = NONMARKOV["max_steps"],
                   spec: SpikingSpec | None = None) -> dict[str, Tensor]:
    """Steps balanced from the paper's start per genome, for each way of running it."""
    cfg = controller_config("snn")
    task = CartPoleTask.nonmarkov(max_steps=max_steps)
    out = {}
    for name, cls in (("as evolved", SpikingController), ("state wiped", WipedStateController),
                      ("static map", StaticMapController)):
        controller = cls(genomes, cfg, spec, period_s=task.control_period_s, action_max=task.action_max,
                         observation_size=task.observation_size)
        out[name] = rollout(task, controller).steps[:, 0]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description="Memory ablation of NEAT-SNN champions (non-Markov task).")
    parser.add_argument("champions", help="folder of snn_seed*.json champions written by snn-neat reproduce table2")
    args = parser.parse_args()
    files = sorted(glob.glob(os.path.join(args.champions, "snn_seed*.json")))
    if not files:
        raise SystemExit(f"no snn_seed*.json files in {args.champions!r}")
    cfg = controller_config("snn")
    parts = [load_genome(f, cfg) for f in files]
    genomes = Genomes(**{k: torch.cat([getattr(g, k) for g in parts], 1) for k in parts[0].tensors()})
    results = ablation_steps(genomes)
    target = NONMARKOV["max_steps"]
    print(f"{len(files)} NEAT-SNN champions from {args.champions}, paper's start, {target} steps")
    print(f"{'run as':<14}{'hold the pole':>15}{'median steps':>14}{'best':>8}")
    for name, steps in results.items():
        print(f"{name:<14}{int((steps >= target).sum()):>9} of {len(files):<3}"
              f"{statistics.median(steps.tolist()):>14g}{int(steps.max()):>8}")


if __name__ == "__main__":
    main()
