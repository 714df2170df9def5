"""Phenotypes: population tensors -> one batched recurrent network for all ``R x P`` genomes.

Semantics (DESIGN.md): recurrent, synchronous, one-step delay. At each update every
non-input node receives ``sum_i w[i, j] y_prev[i]`` over its enabled incoming genes, one
batched matmul for the whole population; no topological sort, any recurrence allowed.

- ``SigmoidNetworks``: ``y_j = sigmoid(4.9 x_j)`` ([NEAT02]'s steepened sigmoid). Input
  nodes hold the inputs, bias nodes hold 1. For a feed-forward genome, ``activate`` with as
  many updates as its longest path gives exactly the feed-forward output.
- ``SpikingNetworks``: every node is an Izhikevich neuron (``snn_torch``); input nodes are
  driven by an input current, bias nodes by a constant current; state (v, u, spikes)
  persists across control steps until ``reset``.
"""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.population import Genomes
from snn_torch.functional.izhikevich import DEFAULT_DT_MS, QIU2019, IzhikevichParams, check_dt
from snn_torch.functional.recurrent import RecurrentState, recurrent_init, recurrent_izhikevich_step

__all__ = ["SigmoidNetworks", "SpikingNetworks", "NEAT_SIGMOID_SLOPE"]

NEAT_SIGMOID_SLOPE = 4.9  # [NEAT02]


def _flat_weights(g: Genomes) -> Tensor:
    w = g.effective_weight()
    return w.reshape(-1, g.num_nodes, g.num_nodes)


class SigmoidNetworks:
    """``R x P`` recurrent sigmoid networks, batched as ``B = R * P``."""

    def __init__(self, genomes: Genomes, config: NEATConfig) -> None:
        self.config = config
        self.batch_shape = (genomes.num_runs, genomes.pop_size)
        self.w = _flat_weights(genomes)
        self.values: Tensor | None = None

    def reset(self, *extra: int) -> None:
        """Zero all node values; ``extra`` adds axes (e.g. several episodes per genome)."""
        B, N = self.w.shape[0], self.w.shape[-1]
        self.values = torch.zeros(B, *extra, N, dtype=self.w.dtype, device=self.w.device)

    def step(self, inputs: Tensor) -> Tensor:
        """One synchronous update. ``inputs[R, P, ..., num_inputs]``; returns all node values."""
        cfg = self.config
        if self.values is None:
            self.reset(*inputs.shape[2:-1])
        vals = self.values
        x = vals.reshape(vals.shape[0], -1, vals.shape[-1]) @ self.w
        y = torch.sigmoid(NEAT_SIGMOID_SLOPE * x).reshape(vals.shape)
        y[..., : cfg.num_inputs] = inputs.reshape(-1, *inputs.shape[2:]).to(y.dtype)
        y[..., cfg.num_inputs : cfg.first_output] = 1.0
        self.values = y
        return y.reshape(*self.batch_shape, *y.shape[1:])

    def activate(self, inputs: Tensor, updates: int) -> Tensor:
        """Reset, clamp the inputs, run ``updates`` updates; return the outputs ``[..., num_outputs]``."""
        self.reset(*inputs.shape[2:-1])
        self.step(inputs)  # place the inputs (and bias) first
        for _ in range(updates):
            y = self.step(inputs)
        return y[..., self.config.first_output : self.config.first_hidden]


class SpikingNetworks:
    """``R x P`` recurrent Izhikevich networks, batched as ``B = R * P``.

    Args:
        genomes: the population.
        config: its layout.
        neuron: Izhikevich parameters for every node (default: Qiu et al.'s).
        dt_ms: integration step (ms).
        i_background: current added to every neuron (mV/ms; the paper's background current).
        i_bias: current driving bias nodes (mV/ms).
    """

    def __init__(self, genomes: Genomes, config: NEATConfig, *, neuron: IzhikevichParams = QIU2019,
                 dt_ms: float = DEFAULT_DT_MS, i_background: float = 0.0, i_bias: float = 20.0) -> None:
        self.config = config
        self.neuron = neuron
        self.dt_ms = check_dt(dt_ms)
        self.batch_shape = (genomes.num_runs, genomes.pop_size)
        self.w = _flat_weights(genomes)
        self.i_background = float(i_background)
        self.i_bias = float(i_bias)
        self.state: RecurrentState | None = None

    def reset(self, *extra: int) -> None:
        B, N = self.w.shape[0], self.w.shape[-1]
        self.state = recurrent_init((B, *extra, N), self.neuron, device=self.w.device, dtype=self.w.dtype)

    def step(self, input_current: Tensor, substeps: int = 1) -> Tensor:
        """Drive input nodes with ``input_current[R, P, ..., num_inputs]`` (mV/ms) for
        ``substeps`` steps of ``dt_ms``; returns spike counts ``[R, P, ..., N]``."""
        cfg = self.config
        if self.state is None:
            self.reset(*input_current.shape[2:-1])
        v = self.state.v
        i_ext = torch.full_like(v, self.i_background)
        i_ext[..., : cfg.num_inputs] += input_current.reshape(-1, *input_current.shape[2:]).to(v.dtype)
        i_ext[..., cfg.num_inputs : cfg.first_output] += self.i_bias
        counts = torch.zeros_like(v)
        state = self.state
        for _ in range(substeps):
            z, state = recurrent_izhikevich_step(i_ext, state, self.w, self.neuron, dt_ms=self.dt_ms, validate=False)
            counts = counts + z
        self.state = state
        return counts.reshape(*self.batch_shape, *counts.shape[1:])
