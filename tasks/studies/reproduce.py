"""Run a study's controller over many seeds in one batch, resumable: ``run_controller``.

All runs of one controller evolve in one batch (run axis R) through ``NEAT.run``, with reporters
for the progress bar, the best-fitness history (Fig. 8) and the checkpoint: after every
``checkpoint_every`` generations the whole state (NEAT state with its RNG streams, the history,
and the study's test state where it has one) is written atomically to ``OUT/<controller>.ckpt``
(``tasks.studies.resumable``), so a reproduction killed at any point resumes with
``resume=True`` and ends with the same table as an uninterrupted one. Solved runs are frozen
(not evaluated again).

A run's score is its solving generation (1-based, as the paper counts); a run that does
not solve within ``generations`` counts as ``generations + 1`` (the paper's 101).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch
from torch import Tensor

from evolution.checkpoint import CheckpointError
from evolution.config import NEATConfig
from evolution.neat import NEAT
from evolution.reporters import BaseReporter, GenerationStatus, TqdmReporter
from tasks.studies.registry import STUDIES, ReproduceError, StudyOptions, study
from tasks.studies.results import ControllerRuns
from tasks.studies.resumable import RunCheckpoint, open_run

__all__ = ["TASKS", "ReproduceError", "ControllerRuns", "StudyOptions", "run_controller", "study_config", "write_report",
           "FIG8_MAX_PAD"]

TASKS = tuple(STUDIES)
# Fig. 8 draws solved runs' final best up to the budget, or this many generations where the
# budget is larger (evolution itself may go on longer; its generations are all drawn).
FIG8_MAX_PAD = 10_000


def study_config(task_name: str, controller: str, options: StudyOptions | None = None, **option_fields) -> NEATConfig:
    """The NEAT config ``run_controller`` evolves ``controller`` with on ``task_name`` under ``options``
    (``STUDIES[task_name].config``; the CLI's memory check reads it too)."""
    return study(task_name).config(controller, _options(options, option_fields))


def write_report(results: dict[str, ControllerRuns], table: str, out: str | os.PathLike, *, command: str,
                 generalization: bool = True) -> list[Path]:
    """The study's report of ``results`` (``STUDIES[table].write_report``). Returns the paths written."""
    return study(table).write_report(results, out, command=command, generalization=generalization)


class _History(BaseReporter):
    """Each generation's best fitness so far per run, ``[R]`` float64 (Fig. 8's data)."""

    def __init__(self, rows: list[Tensor]) -> None:
        self.rows = rows

    def end_generation(self, status: GenerationStatus) -> None:
        self.rows.append(status.best_fitness.detach().cpu().clone())

    def stacked(self, runs: int) -> Tensor:
        return torch.stack(self.rows) if self.rows else torch.zeros(0, runs, dtype=torch.float64)


class _CPUTimed:
    """``solved_fn`` with the CPU seconds its calls took: the test of a solution (DPNV's 100,000
    steps and 625 starts) is part of what a run costs, and not counted in its evaluations."""

    def __init__(self, fn, cpu_s: float = 0.0) -> None:
        self.fn, self.cpu_s = fn, cpu_s

    def __call__(self, genomes, fitness):
        start = time.process_time()
        try:
            return self.fn(genomes, fitness)
        finally:
            self.cpu_s += time.process_time() - start


def _seconds(data: dict, key: str) -> float:
    value = data.get(key, 0.0)  # absent in checkpoints written before it was kept
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= 0 else 0.0


def _checked_history(path: Path, data: dict, neat: NEAT) -> list[Tensor]:
    """A checkpoint's Fig. 8 history (one ``[R]`` float64 row per generation), checked: a crafted or
    damaged file stops here, naming itself."""
    history = data.get("history")
    shape = (neat.generation, neat.num_runs)
    if not isinstance(history, Tensor) or history.dtype != torch.float64 or tuple(history.shape) != shape:
        got = (tuple(history.shape), history.dtype) if isinstance(history, Tensor) else type(history).__name__
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: its history should be {shape} float64 "
                              f"(generations, runs), got {got}")
    return list(history.unbind(0))


def _options(options: StudyOptions | None, fields: dict) -> StudyOptions:
    """``options`` with the ``StudyOptions`` fields given as keywords set on it."""
    return replace(options or StudyOptions(), **fields)


def run_controller(task_name: str, controller: str, seeds: list[int], generations: int | None,
                   out: str | os.PathLike, *, options: StudyOptions | None = None, resume: bool = False,
                   checkpoint_every: int = 1, device: str | torch.device = "cpu", progress: bool = True,
                   stop_after: int | None = None, **option_fields) -> ControllerRuns:
    """Evolve ``controller`` on the study ``task_name`` (``STUDIES``) for each seed (one batch),
    checkpointing to ``out``.

    ``options`` (``StudyOptions``; its fields may also be given as keywords, e.g. ``coding="signed"``):
    the setup (default: the study's first, for the double pole each controller's best) and any field
    of it overridden: the GA (a preset of ``GA_PRESETS``, or ``"tuned"``, the controller's own pick),
    the input coding, the test of a generation (DPNV: ``"species"``, NEAT C++ 1.2.1's champion of the
    best species not tested since its last record, its checks and records kept in the checkpoint, or
    ``"champion"``, each run's overall champion every generation), the fitness starts (DPNV: the mean
    damping fitness from the standard start and ``fitness_starts - 1`` fixed random starts,
    ``tasks.studies.double_pole.damping_fitness_starts``), the fitness and the generalisation starts a
    solution holds (``min_general``, DPNV).
    ``generations``: the budget (None: the study's, ``Study.generations``).

    ``resume`` continues from ``OUT/<controller>.ckpt`` (which must have been written with
    the same task, seeds, resolved options and start genome; the budget may grow); without it an
    existing checkpoint is an error, so a finished reproduction is never overwritten by accident.
    ``stop_after`` (generations in this call) exists for tests of interruption.
    """
    s = study(task_name)
    options = s.options(controller, _options(options, option_fields))
    if checkpoint_every < 1:
        raise ReproduceError(f"checkpoint_every must be >= 1, got {checkpoint_every}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{controller}.ckpt"
    recorded = s.identity(controller, options)
    config = s.config(controller, options)
    if generations is None:
        generations = s.generations(config)
    identity = {"task": task_name, "controller": controller, "seeds": list(seeds), "generations": generations,
                **recorded}
    try:
        neat, data = open_run(path, identity, resume=resume, device=device, missing_ok=True,
                              defaults=StudyOptions.identity_defaults(),
                              fresh=lambda: NEAT(config, seeds=seeds, device=device))
    except ReproduceError as exc:
        if "was written with" not in str(exc) or len(s.setups) == 1:
            raise
        raise ReproduceError(f"{exc}: this call's options are those of setup {options.setup!r}; a checkpoint "
                             "written before setups existed resumes with setup 'neat-2002' (--setup neat-2002)") from None
    config = neat.config
    fitness_fn = s.fitness(controller, config, options)
    solved_fn = s.solved(controller, config, options, neat=neat)
    if data.get("solved_state") is not None and hasattr(solved_fn, "load_state_dict"):
        try:
            solved_fn.load_state_dict(data["solved_state"])
        except ValueError as exc:
            raise CheckpointError(f"checkpoint {str(path)!r} is malformed: {exc}") from None

    timed = None if solved_fn is None else _CPUTimed(solved_fn, _seconds(data, "solve_test_cpu_s"))
    cpu_before = _seconds(data, "cpu_s")
    cpu_start = time.process_time()
    history = _History(_checked_history(path, data, neat) if data else [])
    neat.add_reporter(history)
    bar = neat.add_reporter(TqdmReporter(total=generations, initial=neat.generation, desc=f"{task_name} {controller}",
                                         disable=not progress, file=sys.stderr))

    def records() -> dict:
        state = {"solved_state": solved_fn.state_dict()} if hasattr(solved_fn, "state_dict") else {}
        return {"history": history.stacked(len(seeds)), "cpu_s": cpu_before + time.process_time() - cpu_start,
                "solve_test_cpu_s": 0.0 if timed is None else timed.cpu_s, **state}

    checkpoint = neat.add_reporter(RunCheckpoint(path, identity, generations, every=checkpoint_every, records=records,
                                                 wall_s=float(data.get("wall_s", 0.0))))
    budget = max(generations - neat.generation, 0)
    try:
        neat.run(fitness_fn, budget if stop_after is None else min(budget, stop_after), solved_fn=timed)
    finally:
        bar.end_run(None)  # closed now: a bar closed at exit would draw over an interruption's message
    hist = history.stacked(len(seeds))
    # Runs that solved early keep their final best for the rest of the budget (Fig. 8), drawn
    # up to FIG8_MAX_PAD generations: a budget of 10**12 cannot be padded (nor plotted).
    pad_to = min(generations, max(hist.shape[0], FIG8_MAX_PAD))
    if 0 < hist.shape[0] < pad_to:
        hist = torch.cat([hist, hist[-1:].expand(pad_to - hist.shape[0], -1)])
    return ControllerRuns(controller=controller, seeds=list(seeds), generations=generations,
                          solved_generation=neat.solved_generation.cpu().tolist(),
                          best_fitness=neat.best_fitness.cpu().tolist(), history=hist,
                          champions=neat.best_genomes.to("cpu"), config=config, wall_s=checkpoint.wall_s,
                          extra={"complete": checkpoint.finished(neat), **recorded, "setup": options.setup,
                                 "cpu_s": cpu_before + time.process_time() - cpu_start,
                                 "solve_test_cpu_s": 0.0 if timed is None else timed.cpu_s,
                                 "solved_position": neat.solved_position.cpu().tolist()})
