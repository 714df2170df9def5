"""One random stream per evolutionary run.

Each run owns a ``torch.Generator`` seeded with its own seed, so a run's random numbers, and
hence its whole history, do not depend on which or how many other runs share its batch.
Draws loop over runs (not genomes): one kernel call per run per draw, each covering that
run's whole population.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["RunRNG"]


class RunRNG:
    """Per-run generators on one device. Draws return tensors with a leading run axis."""

    def __init__(self, seeds: list[int], device: torch.device | str = "cpu") -> None:
        if not seeds:
            raise ValueError("seeds must name at least one run")
        for s in seeds:
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < 2**63:
                raise ValueError(f"seeds must be non-negative integers below 2**63, got {s!r}")
        self.seeds = list(seeds)
        self.device = torch.device(device)
        self.generators = [torch.Generator(device=self.device).manual_seed(s) for s in self.seeds]

    def __len__(self) -> int:
        return len(self.generators)

    def rand(self, *shape: int, dtype: torch.dtype = torch.float32) -> Tensor:
        """Uniform [0, 1) draws of shape ``[R, *shape]``."""
        out = torch.empty((len(self.generators), *shape), device=self.device, dtype=dtype)
        for g, row in zip(self.generators, out, strict=True):
            row.uniform_(generator=g)
        return out

    def randn(self, *shape: int, dtype: torch.dtype = torch.float32) -> Tensor:
        """Standard normal draws of shape ``[R, *shape]``."""
        out = torch.empty((len(self.generators), *shape), device=self.device, dtype=dtype)
        for g, row in zip(self.generators, out, strict=True):
            row.normal_(generator=g)
        return out

    def subset(self, runs: list[int]) -> RunRNG:
        """A view of some runs' generators (shared, not copied: draws advance them)."""
        sub = RunRNG.__new__(RunRNG)
        sub.seeds = [self.seeds[r] for r in runs]
        sub.device = self.device
        sub.generators = [self.generators[r] for r in runs]
        return sub

    def get_state(self) -> list[Tensor]:
        return [g.get_state() for g in self.generators]

    def set_state(self, states: list[Tensor]) -> None:
        if len(states) != len(self.generators):
            raise ValueError(f"expected {len(self.generators)} generator states, got {len(states)}")
        for g, s in zip(self.generators, states, strict=True):
            g.set_state(s)
