"""Checkpointed runs for ``snn-neat evolve`` and ``snn-neat xor``, resumed as ``reproduce`` resumes.

``OUT/<name>.ckpt`` holds the NEAT state (RNG streams included), the command's identity (what
it was asked to do) and its own records (statistics rows, wall time). It is written atomically
every ``checkpoint_every`` generations and when the run ends, so a command killed at any point
continues with ``--resume`` to the same bits as an uninterrupted one.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import torch

from evolution.checkpoint import CheckpointError, atomic_torch_save, load_checkpoint_dict
from evolution.neat import NEAT
from evolution.reporters import BaseReporter, GenerationStatus
from tasks.studies.registry import ReproduceError

__all__ = ["RunCheckpoint", "open_run"]


def open_run(path: str | os.PathLike, identity: dict, *, resume: bool, device: str | torch.device,
             fresh: Callable[[], NEAT], missing_ok: bool = False, defaults: dict | None = None) -> tuple[NEAT, dict]:
    """The run to continue: ``path``'s (which needs ``resume``, and the same ``identity``) or
    ``fresh()`` (which needs no ``resume``: a ``--resume`` with nothing to continue is an error,
    not a silent new start, unless ``missing_ok``: one of several checkpoints a command resumes
    may not have been written yet). ``defaults``: the value an identity key had before it was
    recorded, so older checkpoints resume; for a dict-valued key (a config), a dict of the values
    its fields had before they were added. ``generations`` may change on a resume to any budget
    the checkpoint has not passed: the runs not yet solved go on to it. Returns ``(neat, checkpoint)`` (``{}`` for a fresh run).
    The one resume check of every command (``reproduce``, ``evolve``, ``xor``)."""
    path = Path(path)
    defaults = defaults or {}
    if not path.exists():
        if resume and not missing_ok:
            raise ReproduceError(f"--resume: there is no checkpoint {path} to continue; "
                                 "run without --resume to start afresh")
        return fresh(), {}
    if not resume:
        raise ReproduceError(f"{path} exists: pass --resume to continue it, or choose another --out")
    data = load_checkpoint_dict(path, map_location="cpu")
    saved = data.get("identity")
    command = identity.get("command", "reproduce")
    if not isinstance(data.get("neat"), dict):
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: it holds no NEAT state, so it is not a "
                              f"checkpoint of `snn-neat {command}`")
    if not isinstance(saved, dict):
        raise ReproduceError(f"cannot resume {path}: it is not a checkpoint of `snn-neat {command}`")
    for key, value in identity.items():
        written = saved.get(key, defaults.get(key))
        if isinstance(written, dict) and isinstance(defaults.get(key), dict):
            written = {**defaults[key], **written}  # fields added since it was written
        if key == "generations" and _budget_fits(written, value, data["neat"].get("generation")):
            continue  # a new budget, not yet spent: the unsolved runs go on to it
        if written != value:
            raise ReproduceError(f"cannot resume {path}: it was written with {key}={written!r}, "
                                 f"this call asks for {key}={value!r}")
    neat = NEAT.from_state_dict(data["neat"], device=device, name=str(path))
    wall, rows = data.get("wall_s"), data.get("statistics", [])
    if isinstance(wall, bool) or not isinstance(wall, (int, float)) or not 0 <= wall < float("inf"):
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: wall_s is {wall!r:.40}")
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: statistics is not a list of rows")
    return neat, data


def _budget_fits(written, asked, done) -> bool:
    """Whether a resume may change the budget from ``written`` to ``asked`` generations: both
    counts, and the checkpoint (``done`` generations) not past ``asked``. Evolution never reads its
    budget, so a run resumed with a new budget is the run that had it from the start."""
    counts = all(isinstance(v, int) and not isinstance(v, bool) for v in (written, asked, done))
    return counts and asked >= done


class RunCheckpoint(BaseReporter):
    """Writes ``path`` every ``every`` generations, or with ``every=None`` at the end of the first
    generation ``interval_s`` seconds after the last write (a population of large genomes takes
    a while to write, which every generation of a fast task would repeat), and when the run ends
    (its budget of ``generations`` spent, or every run solved). ``records()`` adds the command's
    own entries; add this reporter after those that fill them. ``wall_s``: seconds spent before
    this process."""

    def __init__(self, path: str | os.PathLike, identity: dict, generations: int, *, every: int | None = 1,
                 interval_s: float = 30.0, records: Callable[[], dict] = dict, wall_s: float = 0.0) -> None:
        if every is not None and every < 1:
            raise ReproduceError(f"checkpoint_every must be >= 1, got {every}")
        self.path, self.identity, self.generations, self.every = Path(path), identity, generations, every
        self.interval_s = interval_s
        self.records = records
        self._wall0, self._start = wall_s, time.perf_counter()
        self._last = self._start

    @property
    def wall_s(self) -> float:
        """Seconds of evolution so far, over every process that worked on the run."""
        return self._wall0 + time.perf_counter() - self._start

    def finished(self, neat: NEAT | GenerationStatus) -> bool:
        """The run is over: its budget spent, or every run solved (of a driver or its last status)."""
        done = neat.generations_done if isinstance(neat, GenerationStatus) else neat.generation
        return done >= self.generations or not bool(neat.active_runs.any())

    def due(self, status: GenerationStatus) -> bool:
        if self.every is None:
            return time.perf_counter() - self._last >= self.interval_s
        return status.generations_done % self.every == 0

    def end_generation(self, status: GenerationStatus) -> None:
        if self.due(status) or self.finished(status):
            self.save(status)

    def save(self, status: GenerationStatus) -> Path:
        state = status.state_dict()
        path = atomic_torch_save({"format": state["format"], "version": state["version"], "identity": self.identity,
                                  "neat": state, "wall_s": self.wall_s, **self.records()}, self.path)
        self._last = time.perf_counter()
        return path
