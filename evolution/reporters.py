"""Reporters: what the driver tells each generation, as one status (neat-python's hook names).

``NEAT.tell`` builds a ``GenerationStatus`` once per generation, and only when some reporter
listens: the fitness of the generation just evaluated, each run's best so far and solving
generation, the evaluated population's species and sizes, what breeding did, and a way to take
the driver's whole state (for checkpoints). Reporters read it and nothing else, so this module
knows nothing of the driver; per-run statistics are computed on first use and shared.
"""

from __future__ import annotations

import csv
import functools
import io
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from evolution.checkpoint import atomic_torch_save, atomic_write_bytes

__all__ = ["GenerationStatus", "BaseReporter", "StdOutReporter", "StatisticsReporter", "TqdmReporter", "Checkpointer",
           "mean_std"]


def mean_std(f: Tensor, dim: int = -1) -> tuple[Tensor, Tensor]:
    """Mean and population standard deviation of float64 ``f`` along ``dim``. Where a sum or
    a squared deviation overflows (fitness beyond about 1e150), they are taken over ``f``
    scaled by a power of two to at most 1 in magnitude, which is exact: the statistics of
    finite fitness stay finite. Otherwise torch's, bit for bit."""
    mean, std = f.mean(dim), f.std(dim, unbiased=False)
    if bool(torch.isfinite(mean).all() & torch.isfinite(std).all()):
        return mean, std
    scale = torch.pow(2.0, -torch.frexp(f.abs().amax(dim, keepdim=True)).exponent.to(f.dtype))
    m = (f * scale).mean(dim, keepdim=True) / scale
    sd = (f * scale).std(dim, unbiased=False, keepdim=True) / scale
    return m.squeeze(dim), sd.squeeze(dim)


@dataclass(eq=False)
class GenerationStatus:
    """One generation, as ``NEAT.tell`` leaves it: every reporter hook receives this.

    Attributes:
        generation: 0-based index of the generation just evaluated (``generations_done - 1``).
        fitness: ``[R, P]`` float64, the fitness of the evaluated population (solved runs, which are
            frozen, report their champion's fitness for every genome).
        best_fitness: ``[R]`` float64, each run's best fitness so far.
        solved_generation: ``[R]`` long, the generation (1-based) each run solved in, or -1.
        newly_solved: runs that solved in this generation.
        extinct: runs whose every species died in this generation's breeding and that restarted.
        genes, hidden: ``[R, P]`` long, enabled genes and hidden nodes of each evaluated genome.
        species: ``[R, P]`` long, each evaluated genome's species slot; ``species_ident`` ``[R, S]``
            the slot's run-wide species number; ``species_alive`` ``[R, S]`` bool.
        split_refused: ``[R]`` long, add-node mutations refused for want of a free node slot in
            this generation's breeding (0 for runs not bred).
        offspring: ``[R, S']`` long, the offspring breeding allocated to each species slot (0 for
            runs not bred).
        state_dict: the driver's whole state after this generation (``NEAT.state_dict``).
    """

    generation: int
    fitness: Tensor
    best_fitness: Tensor
    solved_generation: Tensor
    newly_solved: list[int]
    extinct: list[int]
    genes: Tensor
    hidden: Tensor
    species: Tensor
    species_ident: Tensor
    species_alive: Tensor
    split_refused: Tensor
    offspring: Tensor
    state_dict: Callable[[], dict] = field(repr=False)

    @property
    def generations_done(self) -> int:
        return self.generation + 1

    @property
    def num_runs(self) -> int:
        return int(self.fitness.shape[0])

    @property
    def active_runs(self) -> Tensor:
        """Runs still evolving after this generation, ``[R]`` bool."""
        return self.solved_generation < 0

    @property
    def num_solved(self) -> int:
        return int((self.solved_generation >= 0).sum())

    @functools.cached_property
    def run_statistics(self) -> dict[str, Tensor]:
        """Per run, ``[R]`` (CPU, float64 unless said): ``best``, ``mean`` and ``std`` of this
        generation's fitness, ``num_species`` (long), ``mean_genes``, ``mean_hidden``."""
        f = self.fitness.double().cpu()
        rows = [mean_std(f[r]) for r in range(f.shape[0])]  # row by row: the same sums, the same bits
        return {"best": f.amax(1), "mean": torch.stack([m for m, _ in rows]), "std": torch.stack([sd for _, sd in rows]),
                "num_species": self.species_alive.sum(1).cpu(), "mean_genes": self.genes.double().mean(1).cpu(),
                "mean_hidden": self.hidden.double().mean(1).cpu()}


class BaseReporter:
    """Override any hook; all default to doing nothing. Hooks run in this order each generation:
    ``start_generation`` (before evaluation), then after breeding ``found_solution`` (if some run
    solved), ``complete_extinction`` (if some run restarted) and ``end_generation``; ``end_run``
    when ``NEAT.run`` returns (with the last status, or None if no generation ran)."""

    def start_generation(self, generation: int) -> None: ...
    def found_solution(self, status: GenerationStatus) -> None: ...
    def complete_extinction(self, status: GenerationStatus) -> None: ...
    def end_generation(self, status: GenerationStatus) -> None: ...
    def end_run(self, status: GenerationStatus | None) -> None: ...


class StdOutReporter(BaseReporter):
    """One line per generation: best and mean fitness, species, genome size (means over runs)."""

    def __init__(self, every: int = 1) -> None:
        self.every = every
        self._t0 = time.perf_counter()

    def end_generation(self, status: GenerationStatus) -> None:
        if status.generation % self.every:
            return
        f = status.fitness.double()
        st = status.run_statistics
        elapsed = time.perf_counter() - self._t0
        print(f"gen {status.generation:4d}  best {mean_std(f.amax(1))[0].item():10.4g}  "
              f"mean {mean_std(f.flatten())[0].item():10.4g}  "
              f"species {st['num_species'].double().mean().item():5.1f}  "
              f"genes {status.genes.double().mean().item():6.2f}  "
              f"hidden {status.hidden.double().mean().item():5.2f}  "
              f"solved {status.num_solved}/{status.num_runs}  {elapsed:7.1f} s", flush=True)

    def complete_extinction(self, status: GenerationStatus) -> None:
        print(f"gen {status.generation}: complete extinction in runs {status.extinct}; restarted", flush=True)


class StatisticsReporter(BaseReporter):
    """Per generation and run: best, mean and std of fitness, species, genes, hidden nodes.

    ``rows`` holds dicts; ``save_csv`` writes them atomically. ``best_fitness()`` gives the
    ``[generations, R]`` tensor of best fitness per generation (the paper's Fig. 8 data).
    """

    FIELDS = ["generation", "run", "best_fitness", "mean_fitness", "std_fitness", "num_species",
              "mean_genes", "mean_hidden", "split_refused"]

    def __init__(self) -> None:
        self.rows: list[dict] = []

    def end_generation(self, status: GenerationStatus) -> None:
        st = status.run_statistics
        refused = status.split_refused.cpu().tolist()
        for r in range(status.num_runs):
            self.rows.append({
                "generation": status.generation, "run": r, "best_fitness": st["best"][r].item(),
                "mean_fitness": st["mean"][r].item(), "std_fitness": st["std"][r].item(),
                "num_species": int(st["num_species"][r]), "mean_genes": st["mean_genes"][r].item(),
                "mean_hidden": st["mean_hidden"][r].item(), "split_refused": int(refused[r]),
            })

    def best_fitness(self) -> Tensor:
        gens = sorted({row["generation"] for row in self.rows})
        runs = sorted({row["run"] for row in self.rows})
        out = torch.full((len(gens), len(runs)), float("nan"), dtype=torch.float64)
        gi = {g: i for i, g in enumerate(gens)}
        for row in self.rows:
            out[gi[row["generation"]], row["run"]] = row["best_fitness"]
        return out

    def save_csv(self, path: str | os.PathLike) -> Path:
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=self.FIELDS)
        writer.writeheader()
        writer.writerows(self.rows)
        return atomic_write_bytes(path, buf.getvalue().encode())


class TqdmReporter(BaseReporter):
    """A progress bar over generations showing the best fitness and runs solved. Keyword
    arguments go to ``tqdm`` (``initial``, ``desc``, ``disable``, ``file``, ...)."""

    def __init__(self, total: int | None = None, **tqdm_kwargs) -> None:
        self.total = total
        self.kwargs = {"desc": "NEAT", **tqdm_kwargs}
        self.bar = None

    def start_generation(self, generation: int) -> None:
        if self.bar is None:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=self.total, unit="gen", **self.kwargs)

    def end_generation(self, status: GenerationStatus) -> None:
        if self.bar is not None:
            self.bar.set_postfix(best=f"{status.fitness.double().amax().item():.4g}",
                                 solved=f"{status.num_solved}/{status.num_runs}")
            self.bar.update(1)

    def end_run(self, status: GenerationStatus | None) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class Checkpointer(BaseReporter):
    """Save the whole state every ``every`` generations to ``{prefix}{generation}.pt``.

    Files are written atomically, so a crash mid-write leaves the previous checkpoint whole.
    ``keep`` bounds how many recent files stay on disk (None keeps all).
    """

    def __init__(self, every: int = 10, prefix: str | os.PathLike = "neat-checkpoint-", keep: int | None = None) -> None:
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        self.every = every
        self.prefix = str(prefix)
        self.keep = keep
        self.written: list[Path] = []

    def end_generation(self, status: GenerationStatus) -> None:
        if status.generations_done % self.every == 0:
            self.written.append(atomic_torch_save(status.state_dict(), f"{self.prefix}{status.generations_done}.pt"))
            if self.keep is not None:
                while len(self.written) > self.keep:
                    self.written.pop(0).unlink(missing_ok=True)
