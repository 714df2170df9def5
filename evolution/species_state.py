"""The species slots' state (``SpeciesState``), on its own so that the C kernels
(``evolution.kernels.select``) can name it without importing ``evolution.speciate``, which
imports them; ``evolution.speciate`` re-exports both names."""

from __future__ import annotations

from dataclasses import dataclass, fields

import torch
from torch import Tensor

from evolution.population import run_index

__all__ = ["SpeciesState", "empty_species"]


@dataclass
class SpeciesState:
    """Per-run species slots, ``[R, S, ...]``.

    ``alive``: the slot holds a species. ``rep_*``: its representative genome, as the distance
    reads it (``rep_weight`` holds its ``mutation_num`` where genomes carry one: ``distance_view``).
    ``best_fitness``: best member fitness ever seen. ``last_improved``, ``created``:
    generations. ``next_id`` and ``ident``: a run-wide species number, for reports.
    ``obliterated`` (``[R, S]``): marked stagnant for good (``NEATConfig.obliterate_interval``).
    ``run_best`` and ``run_stale`` (``[R]``): the run's best fitness ever and the generations
    since it last improved (``NEATConfig.population_stagnation``). These three default to
    their fresh values, so states saved before they existed still load.
    """

    alive: Tensor
    rep_conn: Tensor
    rep_weight: Tensor
    rep_sigma: Tensor
    best_fitness: Tensor
    last_improved: Tensor
    created: Tensor
    ident: Tensor
    next_id: Tensor  # [R]
    obliterated: Tensor | None = None  # [R, S] bool
    run_best: Tensor | None = None  # [R] float64
    run_stale: Tensor | None = None  # [R] long

    def __post_init__(self) -> None:
        R, dev = (self.alive.shape[0] if self.alive.dim() else 0), self.alive.device
        if self.obliterated is None:
            self.obliterated = torch.zeros(self.alive.shape, dtype=torch.bool, device=dev)
        if self.run_best is None:
            self.run_best = torch.full((R,), -torch.inf, dtype=torch.float64, device=dev)
        if self.run_stale is None:
            self.run_stale = torch.zeros(R, dtype=torch.long, device=dev)
        # the C kernels index by these shapes: refuse others here (a crafted checkpoint, say)
        for name, shape in (("obliterated", tuple(self.alive.shape)), ("run_best", (R,)), ("run_stale", (R,))):
            if self.alive.dim() != 2:  # NEAT's own checks name the species slots' shape
                break
            t = getattr(self, name)
            if not isinstance(t, Tensor) or tuple(t.shape) != shape:
                got = tuple(t.shape) if isinstance(t, Tensor) else type(t).__name__
                raise ValueError(f"SpeciesState.{name} should have shape {shape}, got {got}")

    @property
    def capacity(self) -> int:
        return self.alive.shape[1]

    def tensors(self) -> dict[str, Tensor]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def grow(self, new_capacity: int) -> SpeciesState:
        """Pad every per-slot tensor to ``new_capacity`` slots (dead, empty)."""
        extra = new_capacity - self.capacity
        out = {}
        for name, t in self.tensors().items():
            if t.dim() == 1:  # per run: next_id, run_best, run_stale
                out[name] = t
                continue
            pad = torch.zeros((t.shape[0], extra, *t.shape[2:]), dtype=t.dtype, device=t.device)
            if name == "best_fitness":
                pad.fill_(-torch.inf)
            out[name] = torch.cat([t, pad], 1)
        return SpeciesState(**out)

    def select_runs(self, runs: Tensor | list[int]) -> SpeciesState:
        """A copy of runs ``runs`` (indices, or an ``[R]`` bool mask)."""
        idx = run_index(runs, self.alive.device)
        return SpeciesState(**{k: v.index_select(0, idx) for k, v in self.tensors().items()})


def empty_species(R: int, N: int, capacity: int, *, device: torch.device, dtype: torch.dtype) -> SpeciesState:
    return SpeciesState(
        alive=torch.zeros(R, capacity, dtype=torch.bool, device=device),
        rep_conn=torch.zeros(R, capacity, N, N, dtype=torch.bool, device=device),
        rep_weight=torch.zeros(R, capacity, N, N, dtype=dtype, device=device),
        rep_sigma=torch.zeros(R, capacity, dtype=dtype, device=device),
        best_fitness=torch.full((R, capacity), -torch.inf, dtype=torch.float64, device=device),
        last_improved=torch.zeros(R, capacity, dtype=torch.long, device=device),
        created=torch.zeros(R, capacity, dtype=torch.long, device=device),
        ident=torch.zeros(R, capacity, dtype=torch.long, device=device),
        next_id=torch.zeros(R, dtype=torch.long, device=device),
    )
