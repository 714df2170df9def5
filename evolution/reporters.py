"""Reporters: hooks the driver calls each generation (neat-python's hook names)."""

from __future__ import annotations

import csv
import io
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from evolution.checkpoint import atomic_write_bytes

if TYPE_CHECKING:
    from evolution.neat import NEAT
    from evolution.reproduce import ReproductionInfo

__all__ = ["BaseReporter", "StdOutReporter", "StatisticsReporter", "TqdmReporter", "Checkpointer"]


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


class BaseReporter:
    """Override any hook; all default to doing nothing."""

    def start_generation(self, neat: NEAT) -> None: ...
    def post_evaluate(self, neat: NEAT, fitness: Tensor) -> None: ...
    def post_reproduction(self, neat: NEAT, info: ReproductionInfo) -> None: ...
    def end_generation(self, neat: NEAT) -> None: ...
    def found_solution(self, neat: NEAT, runs: list[int]) -> None: ...
    def complete_extinction(self, neat: NEAT, runs: list[int]) -> None: ...
    def end_run(self, neat: NEAT) -> None: ...


class StdOutReporter(BaseReporter):
    """One line per generation: best and mean fitness, species, genome size (run 0 or all)."""

    def __init__(self, every: int = 1) -> None:
        self.every = every
        self._t0 = time.perf_counter()

    def post_evaluate(self, neat: NEAT, fitness: Tensor) -> None:
        if neat.generation % self.every:
            return
        f = fitness.double()
        elapsed = time.perf_counter() - self._t0
        n_species = neat.species_state.alive.sum(1).double().mean().item()
        print(f"gen {neat.generation:4d}  best {mean_std(f.amax(1))[0].item():10.4g}  "
              f"mean {mean_std(f.flatten())[0].item():10.4g}  "
              f"species {n_species:5.1f}  genes {neat.genomes.num_genes().double().mean().item():6.2f}  "
              f"hidden {neat.genomes.num_hidden(neat.config).double().mean().item():5.2f}  "
              f"solved {int((neat.solved_generation >= 0).sum())}/{neat.num_runs}  {elapsed:7.1f} s", flush=True)

    def complete_extinction(self, neat: NEAT, runs: list[int]) -> None:
        print(f"gen {neat.generation}: complete extinction in runs {runs}; restarted", flush=True)


class StatisticsReporter(BaseReporter):
    """Per generation and run: best, mean and std of fitness, species, genes, hidden nodes.

    ``rows`` holds dicts; ``save_csv`` writes them atomically. ``best_fitness()`` gives the
    ``[generations, R]`` tensor of best fitness per generation (the paper's Fig. 8 data).
    """

    FIELDS = ["generation", "run", "best_fitness", "mean_fitness", "std_fitness", "num_species",
              "mean_genes", "mean_hidden", "split_refused"]

    def __init__(self) -> None:
        self.rows: list[dict] = []
        self._pending: dict[int, dict] = {}

    def post_evaluate(self, neat: NEAT, fitness: Tensor) -> None:
        f = fitness.double().cpu()
        genes = neat.genomes.num_genes().double().mean(1).cpu()
        hidden = neat.genomes.num_hidden(neat.config).double().mean(1).cpu()
        species = neat.species_state.alive.sum(1).cpu()
        for r in range(f.shape[0]):
            mean, std = mean_std(f[r])  # row by row, as before: the same sums, the same bits
            self._pending[r] = {
                "generation": neat.generation, "run": r, "best_fitness": f[r].max().item(),
                "mean_fitness": mean.item(), "std_fitness": std.item(),
                "num_species": int(species[r]), "mean_genes": genes[r].item(),
                "mean_hidden": hidden[r].item(), "split_refused": 0,
            }

    def post_reproduction(self, neat: NEAT, info: ReproductionInfo) -> None:
        # ``info`` has a row per run still evolving (solved runs are frozen, not bred), in run order.
        refused = info.split_refused.cpu().tolist()
        evolving = torch.nonzero(neat.active_runs).flatten().tolist()
        for r, count in zip(evolving, refused, strict=True):
            if r in self._pending:
                self._pending[r]["split_refused"] = int(count)

    def end_generation(self, neat: NEAT) -> None:
        self.rows.extend(self._pending[r] for r in sorted(self._pending))
        self._pending = {}

    def end_run(self, neat: NEAT) -> None:
        self.end_generation(neat)

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
    """A progress bar over generations showing the best fitness and runs solved."""

    def __init__(self, total: int | None = None, **tqdm_kwargs) -> None:
        self.total = total
        self.kwargs = tqdm_kwargs
        self.bar = None

    def start_generation(self, neat: NEAT) -> None:
        if self.bar is None:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=self.total, desc="NEAT", unit="gen", **self.kwargs)

    def post_evaluate(self, neat: NEAT, fitness: Tensor) -> None:
        if self.bar is not None:
            self.bar.set_postfix(best=f"{fitness.double().amax().item():.4g}",
                                 solved=f"{int((neat.solved_generation >= 0).sum())}/{neat.num_runs}")

    def end_generation(self, neat: NEAT) -> None:
        if self.bar is not None:
            self.bar.update(1)

    def end_run(self, neat: NEAT) -> None:
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

    def end_generation(self, neat: NEAT) -> None:
        if neat.generation % self.every == 0:
            self.written.append(neat.save_checkpoint(f"{self.prefix}{neat.generation}.pt"))
            if self.keep is not None:
                while len(self.written) > self.keep:
                    self.written.pop(0).unlink(missing_ok=True)
