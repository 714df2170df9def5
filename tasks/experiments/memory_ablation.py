"""Does a NEAT-SNN champion use memory? Run it with its state carried, wiped, or settled.

    python -m tasks.experiments.memory_ablation results/table2/champions

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
from evolution.population import Genomes
from snn_torch.functional.fused_cpu import fused_recurrent_izhikevich_steps
from snn_torch.functional.recurrent import recurrent_init, recurrent_izhikevich_step
from tasks.cartpole import DEFAULT_PLANT
from tasks.controllers import SpikingPolicy, SpikingSpec, closed_loop, normalized_inputs
from tasks.experiments.cartpole import NONMARKOV, controller_config, nonmarkov_start

__all__ = ["WipedStatePolicy", "StaticMapPolicy", "ablation_steps"]


class WipedStatePolicy(SpikingPolicy):
    """The champion with its network state and rate window reset before every control step."""

    def act(self, plant_state: Tensor) -> tuple[Tensor, Tensor]:
        self.state = recurrent_init(self.state.v.shape, self.spec.neuron, dtype=self.state.v.dtype,
                                    device=self.state.v.device)
        self.history.zero_()
        self.step_index = 0
        return super().act(plant_state)


class StaticMapPolicy(SpikingPolicy):
    """A memoryless map of (x, theta): from rest, settle ``settle_ms``, then decode one window."""

    settle_ms: float = 160.0

    def _run(self, i_ext: Tensor, state, substeps: int):
        if self.fused:
            return fused_recurrent_izhikevich_steps(i_ext, state, self.w, self.spec.neuron, dt_ms=self.spec.dt_ms,
                                                    substeps=substeps)
        counts = torch.zeros_like(i_ext)
        for _ in range(substeps):
            z, state = recurrent_izhikevich_step(i_ext, state, self.w, self.spec.neuron, dt_ms=self.spec.dt_ms,
                                                 validate=False)
            counts = counts + z
        return counts, state

    def act(self, plant_state: Tensor) -> tuple[Tensor, Tensor]:
        spec = self.spec
        i_ext = torch.full_like(self.state.v, spec.i_background)
        i_ext[:, :2] += spec.i_input_max * normalized_inputs(plant_state, self.plant).to(i_ext.dtype)
        state = recurrent_init(self.state.v.shape, spec.neuron, dtype=self.state.v.dtype, device=self.state.v.device)
        _, state = self._run(i_ext, state, int(round(self.settle_ms / spec.dt_ms)))
        window = spec.rate_window_steps * self.substeps
        counts, _ = self._run(i_ext, state, window)
        rates = counts / (spec.rate_window_steps * self.window_s)  # Hz
        drive = torch.cumsum(rates * self.w_out, -1)[:, -1]
        return 10.0 * (2.0 / (1.0 + torch.exp(-self.sigma * drive)) - 1.0), counts


def ablation_steps(genomes: Genomes, *, max_steps: int = NONMARKOV["max_steps"],
                   spec: SpikingSpec | None = None) -> dict[str, Tensor]:
    """Steps balanced from the paper's start per genome, for each way of running it."""
    spec = SpikingSpec() if spec is None else spec
    cfg = controller_config("snn")
    tau = NONMARKOV["tau_s"]
    B = genomes.num_runs * genomes.pop_size
    out = {}
    for name, cls, fused_loop in (("as evolved", SpikingPolicy, True), ("state wiped", WipedStatePolicy, False),
                                  ("static map", StaticMapPolicy, False)):
        policy = cls(genomes, cfg, spec, tau, DEFAULT_PLANT)
        policy.loop_fused = policy.loop_fused and fused_loop  # the ablations step in Python
        steps, _ = closed_loop(policy, nonmarkov_start(B, dtype=genomes.weight.dtype), tau_s=tau,
                               max_steps=max_steps)
        out[name] = steps
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
