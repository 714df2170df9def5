"""XOR, the classic NEAT sanity check ([NEAT02] section 4.1), as a batched fitness function."""

from __future__ import annotations

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.population import Genomes
from snn_torch.modules.recurrent import PopulationRecurrentSigmoid

__all__ = ["XOR_CONFIG", "xor_outputs", "xor_fitness", "xor_solved"]

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

