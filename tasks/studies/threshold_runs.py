"""Evolving to a reward threshold on a noisy fitness, batched over runs.

Training fitness over a few episodes is noisy: a genome can reach a plant's reward threshold in
training and fall short on other episodes. So, for every run of a batched ``NEAT`` (``R`` runs
in one population, each stopping on its own):

* a generation whose best training fitness reaches the threshold has its ``CONFIRM_CANDIDATES``
  (5) fittest genomes that reached it checked on ``VALIDATION_EPISODES`` (100) held-out episodes,
  the same ones every generation (seeded by ``VALIDATION_SEED + seed``, the run's seed);
* a genome passes when its held-out mean less ``CONFIDENCE_Z`` (2) standard errors reaches the
  threshold (``held_out_lower_bound``); the run stops (it is marked solved in ``NEAT.tell``,
  which freezes it) when one passes: that genome, the best passing one on the held-out
  episodes, is the run's champion;
* where none passed within the budget, the champion is the best on the held-out episodes
  among the final generation's ``FINAL_CANDIDATES`` (20) fittest and the run's best-ever
  genome (one picked on noisy training fitness alone tests worse);
* the champion is then tested on ``TEST_EPISODES`` (100) fresh episodes, seeded by
  ``TEST_SEED + seed``.

Scores are ``task.fitness`` of the rollouts (a return, or steps survived); held-out and test
episodes come from ``rollout(task, make_controller(genomes, config, task, controller),
episodes=..., seed=...)``. ``ThresholdRuns`` does the bookkeeping as a reporter of the ``NEAT``
and as its ``solved_fn``; its ``state_dict`` goes into a checkpoint, so a resumed run continues
to the same records. ``evolve_to_threshold`` runs the whole thing. ``snn-neat evolve ENV``
(``tasks.studies.evolve_env``) and ``experiments.classic_control`` both use it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field, fields

import torch
from torch import Tensor

from evolution.checkpoint import CheckpointError
from evolution.config import NEATConfig
from evolution.neat import NEAT
from evolution.phenotype import SigmoidSpec, SpikingSpec, make_controller
from evolution.population import Genomes
from evolution.reporters import BaseReporter, GenerationStatus
from evolution.rollout import rollout
from evolution.task import Task

__all__ = ["CONFIDENCE_Z", "held_out_lower_bound", "CONFIRM_CANDIDATES", "FINAL_CANDIDATES", "VALIDATION_EPISODES", "TEST_EPISODES", "VALIDATION_SEED",
           "TEST_SEED", "RunRecord", "ThresholdRuns", "episode_scores", "evolve_to_threshold"]

CONFIRM_CANDIDATES = 5  # genomes that reached the threshold in training, checked on the held-out episodes
FINAL_CANDIDATES = 20  # of the final generation, checked when no genome was confirmed
VALIDATION_EPISODES = 100  # held-out episodes per check
# A genome passes the held-out check when its held-out mean lies this many standard errors above the
# threshold (a one-sided lower bound of about 98 %): a champion confirmed just at the threshold tests
# below it about half the time (2026-12-07, 32 held-out episodes and no margin: Pendulum-v1 and
# Acrobot-v1 champions confirmed at the threshold tested at -203 to -228 and -101 to -105).
CONFIDENCE_Z = 2.0
TEST_EPISODES = 100  # the champion's test (gymnasium's criterion: the mean of 100 episodes)
VALIDATION_SEED, TEST_SEED = 20_000_000, 10_000_000  # + the run's seed


Controller = str | SpikingSpec | SigmoidSpec  # what make_controller takes: a name or a spec


def episode_scores(task: Task, genomes: Genomes, config: NEATConfig, controller: Controller, episodes: int,
                   seed: int) -> Tensor:
    """``[G, episodes]`` float64: ``task.fitness`` (return or steps) of each of the genomes of
    ``genomes`` (``G = R * P``) on ``episodes`` episodes seeded by ``seed``."""
    result = rollout(task, make_controller(genomes, config, task, controller), episodes=episodes, seed=seed)
    return result.fitness(task.fitness)


def held_out_lower_bound(scores: Tensor) -> Tensor:
    """``[G]``: each row's mean of ``scores [G, episodes]`` less ``CONFIDENCE_Z`` standard errors
    (sample std over sqrt(episodes)); the mean itself for a single episode."""
    n = scores.shape[1]
    if n < 2:
        return scores.mean(1)
    return scores.mean(1) - CONFIDENCE_Z * scores.std(1, correction=1) / math.sqrt(n)


@dataclass
class RunRecord:
    """One run's record. Generations count from 1 (the initial population); episodes are
    genome-episodes of training (``pop_size`` x episodes per genome, per generation); seconds
    are this run's share of the batch's (each generation's CPU and wall time split evenly over
    the runs it evaluated), summed over every process that worked on the run.

    Attributes:
        seed: the run's seed.
        history: best training fitness of each generation the run evaluated.
        checks: per generation, the best held-out mean of the genomes checked (None: none was).
        episodes, validation_episodes: training and held-out episodes spent.
        cpu_s, wall_s: CPU seconds (``time.process_time``) and wall seconds spent, the
            champion's pick and test included.
        train_*: the first generation whose best training fitness reached the threshold (-1:
            none), and the episodes and seconds spent up to its end (None: not reached).
        confirmed_*: the generation whose genome passed the held-out check (-1: none), and the
            episodes and seconds spent up to its end (None: none did).
        champion_from: "confirmed" or "final" (picked after the budget, see the module docstring).
        champion_validation: the champion's mean on the held-out episodes.
        test_mean, test_worst, test_std: its test (population std), over ``test_episodes``.
        champion_hidden, champion_genes: its hidden nodes and connection genes.
    """

    seed: int
    history: list[float] = field(default_factory=list)
    checks: list[float | None] = field(default_factory=list)
    episodes: int = 0
    validation_episodes: int = 0
    cpu_s: float = 0.0
    wall_s: float = 0.0
    train_generation: int = -1
    train_episodes: int | None = None
    train_cpu_s: float | None = None
    train_wall_s: float | None = None
    confirmed_generation: int = -1
    confirmed_episodes: int | None = None
    confirmed_cpu_s: float | None = None
    confirmed_wall_s: float | None = None
    champion_from: str = ""
    champion_validation: float | None = None
    test_episodes: int = 0
    test_mean: float | None = None
    test_worst: float | None = None
    test_std: float | None = None
    champion_hidden: int | None = None
    champion_genes: int | None = None

    @classmethod
    def from_dict(cls, data: dict) -> RunRecord:
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})

    @property
    def generations(self) -> int:
        """Generations the run evaluated."""
        return len(self.history)


def _put(into: Genomes, run: int, genomes: Genomes) -> None:
    """Write the ``[1, K]`` ``genomes`` into run ``run`` of ``into`` (``[R, K]``)."""
    for name, t in into.tensors().items():
        t[run] = getattr(genomes, name)[0]


def _empty(genomes: Genomes, runs: int, k: int) -> Genomes:
    """A zeroed ``[runs, k]`` population shaped like ``genomes``."""
    return Genomes(**{name: torch.zeros((runs, k, *t.shape[2:]), dtype=t.dtype, device=t.device)
                      for name, t in genomes.tensors().items()})


class ThresholdRuns(BaseReporter):
    """The per-run bookkeeping of the module docstring for ``neat``'s runs (add it as the first
    reporter and pass ``solved`` as ``NEAT.run``'s ``solved_fn``; ``evolve_to_threshold`` does).

    Args:
        neat: the driver; its seeds are the runs' seeds.
        task, controller: the plant, and the controller name or spec ``make_controller`` takes.
        threshold: the score a run must reach (None: no threshold; every run spends its budget).
        episodes_per_genome: training episodes behind each genome's fitness (for the counts).
        validation_episodes: held-out episodes per check.
        state: ``state_dict()`` of a checkpoint, to continue from.
    """

    def __init__(self, neat: NEAT, task: Task, controller: Controller, threshold: float | None, *,
                 episodes_per_genome: int,
                 validation_episodes: int = VALIDATION_EPISODES, state: dict | None = None) -> None:
        self.neat, self.task, self.controller, self.config = neat, task, controller, neat.config
        self.threshold = None if threshold is None else float(threshold)
        self.episodes_per_genome, self.validation_episodes = int(episodes_per_genome), int(validation_episodes)
        seeds = list(neat.rng.seeds)
        R, genomes = len(seeds), neat.ask()
        self.final_k = min(FINAL_CANDIDATES, self.config.pop_size)
        if state:
            self._restore(state, seeds, genomes)
        else:
            self.records = [RunRecord(seed=s) for s in seeds]
            self.confirmed, self.final = _empty(genomes, R, 1), _empty(genomes, R, self.final_k)
        self.champions: Genomes | None = None
        self._active: list[int] = []
        self._clock = (0.0, 0.0)

    def _restore(self, state: dict, seeds: list[int], genomes: Genomes) -> None:
        """Records and genomes from ``state_dict()``, checked against the driver's runs."""
        try:
            self.records = [RunRecord.from_dict(r) for r in state["records"]]
            self.confirmed = Genomes(**{k: v.to(self.neat.device) for k, v in state["confirmed"].items()})
            self.final = Genomes(**{k: v.to(self.neat.device) for k, v in state["final"].items()})
        except (KeyError, TypeError, AttributeError) as exc:
            raise CheckpointError(f"the checkpoint's run records are malformed ({type(exc).__name__}: {exc})") from None
        R, tail = len(seeds), {k: tuple(v.shape[2:]) for k, v in genomes.tensors().items()}
        for name, held, k in (("confirmed", self.confirmed, 1), ("final", self.final, self.final_k)):
            shapes = {n: tuple(v.shape) for n, v in held.tensors().items()}
            if shapes != {n: (R, k, *t) for n, t in tail.items()}:
                raise CheckpointError(f"the checkpoint's {name} genomes have shapes {shapes}, not those of "
                                      f"{R} runs x {k}")
        if [r.seed for r in self.records] != seeds:
            raise CheckpointError(f"the checkpoint's run records are for seeds {[r.seed for r in self.records]}, "
                                  f"its NEAT state for {seeds}")

    def state_dict(self) -> dict:
        """What a checkpoint keeps (records as plain data, genomes as CPU tensors)."""
        return {"records": [asdict(r) for r in self.records],
                "confirmed": {k: v.detach().cpu().clone() for k, v in self.confirmed.tensors().items()},
                "final": {k: v.detach().cpu().clone() for k, v in self.final.tensors().items()}}

    def _scores(self, genomes: Genomes, seed: int, episodes: int) -> Tensor:
        return episode_scores(self.task, genomes, self.config, self.controller, episodes, seed)

    # --- NEAT.run hooks -------------------------------------------------------------------
    def start_generation(self, generation: int) -> None:
        self._clock = (time.process_time(), time.perf_counter())

    def solved(self, genomes: Genomes, fitness: Tensor) -> Tensor:
        """``NEAT.run``'s ``solved_fn``: ``genomes [A, P]`` and ``fitness [A, P]`` of the ``A``
        unsolved runs; records the generation and checks genomes at the threshold. Returns
        ``[A, P]`` bool: the genomes that passed the held-out check."""
        runs = torch.nonzero(self.neat.active_runs).flatten().tolist()
        generation = self.neat.generation + 1
        P = genomes.pop_size
        solved = torch.zeros(fitness.shape, dtype=torch.bool, device=fitness.device)
        self._active = runs
        for i, r in enumerate(runs):
            rec, f = self.records[r], fitness[i]
            best = float(f.max())
            rec.history.append(best)
            rec.checks.append(None)
            rec.episodes += P * self.episodes_per_genome
            mine = genomes.select_runs([i])
            top = f.topk(self.final_k).indices
            _put(self.final, r, mine.gather(top.unsqueeze(0)))
            if self.threshold is None or best < self.threshold:
                continue
            if rec.train_generation < 0:
                rec.train_generation, rec.train_episodes = generation, rec.episodes
            k = min(CONFIRM_CANDIDATES, int((f >= self.threshold).sum()))
            idx = f.topk(k).indices
            candidates = mine.gather(idx.unsqueeze(0))
            scores = self._scores(candidates, VALIDATION_SEED + rec.seed, self.validation_episodes)
            held_out = scores.mean(1)
            rec.validation_episodes += k * self.validation_episodes
            rec.checks[-1] = float(held_out.max())
            passed = held_out_lower_bound(scores) >= self.threshold
            if bool(passed.any()):
                solved[i, idx[passed.to(idx.device)]] = True
                pick = int(torch.where(passed, held_out, -math.inf).argmax())
                rec.confirmed_generation, rec.confirmed_episodes = generation, rec.episodes
                rec.champion_validation, rec.champion_from = float(held_out[pick]), "confirmed"
                _put(self.confirmed, r, candidates.gather(torch.tensor([[pick]], device=candidates.device)))
        return solved

    def end_generation(self, status: GenerationStatus) -> None:
        cpu0, wall0 = self._clock
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        generation = status.generations_done
        for r in self._active:
            rec = self.records[r]
            rec.cpu_s += cpu / len(self._active)
            rec.wall_s += wall / len(self._active)
            if rec.train_generation == generation and rec.train_cpu_s is None:
                rec.train_cpu_s, rec.train_wall_s = rec.cpu_s, rec.wall_s
            if rec.confirmed_generation == generation:
                rec.confirmed_cpu_s, rec.confirmed_wall_s = rec.cpu_s, rec.wall_s
        self._active = []

    # --- the whole run --------------------------------------------------------------------
    def run(self, fitness: Callable[[Genomes], Tensor], generations: int, *, reporters: Iterable[BaseReporter] = (),
            test_episodes: int = TEST_EPISODES, stop_after: int | None = None) -> Genomes | None:
        """Evolve until each run is confirmed at the threshold or ``generations`` (a total,
        counting those the driver already ran) are spent; then pick and test each champion
        (``finish``) and return them. ``reporters`` are added after this one (a checkpoint's
        reporter may read ``state_dict``); ``stop_after`` (generations in this call) stops early,
        without champions (None is returned), for tests of interruption."""
        neat = self.neat
        # one tiny rollout first, so the first generation's time does not include loading or compiling kernels
        first = neat.ask().gather(torch.zeros(neat.num_runs, 1, dtype=torch.long, device=neat.device))
        rollout(self.task, make_controller(first, self.config, self.task, self.controller), episodes=1, max_steps=2)
        if self not in neat.reporters:
            neat.add_reporter(self)
        for reporter in reporters:
            neat.add_reporter(reporter)
        budget = max(0, generations - neat.generation)
        neat.run(fitness, budget if stop_after is None else min(budget, stop_after), solved_fn=self.solved)
        if neat.generation < generations and bool(neat.active_runs.any()):
            return None  # stopped early
        return self.finish(test_episodes)

    # --- after the budget ----------------------------------------------------------------
    def finish(self, test_episodes: int = TEST_EPISODES) -> Genomes:
        """Each run's champion (``[R, 1]``, also kept as ``champions``), tested on
        ``test_episodes`` episodes; fills the records' champion and test fields."""
        best_ever = self.neat.best_genomes
        picked = []
        for r, rec in enumerate(self.records):
            cpu0, wall0 = time.process_time(), time.perf_counter()
            if rec.confirmed_generation > 0:
                champion = self.confirmed.select_runs([r])
            else:  # the best on the held-out episodes of the last fittest and the best-ever
                candidates = Genomes(**{k: torch.cat([v[r:r + 1], getattr(best_ever, k)[r:r + 1]], 1)
                                        for k, v in self.final.tensors().items()})
                held_out = self._scores(candidates, VALIDATION_SEED + rec.seed, self.validation_episodes).mean(1)
                rec.validation_episodes += candidates.pop_size * self.validation_episodes
                pick = int(held_out.argmax())
                champion = candidates.gather(torch.tensor([[pick]], device=candidates.device))
                rec.champion_validation, rec.champion_from = float(held_out[pick]), "final"
            test = self._scores(champion, TEST_SEED + rec.seed, test_episodes)[0]
            rec.test_episodes = test_episodes
            rec.test_mean, rec.test_worst = float(test.mean()), float(test.min())
            rec.test_std = float(test.std(correction=0))
            rec.champion_hidden = int(champion.num_hidden(self.config)[0, 0])
            rec.champion_genes = int(champion.num_genes()[0, 0])
            rec.cpu_s += time.process_time() - cpu0
            rec.wall_s += time.perf_counter() - wall0
            picked.append(champion)
        self.champions = Genomes(**{k: torch.cat([getattr(c, k) for c in picked]) for k in picked[0].tensors()})
        return self.champions


def evolve_to_threshold(neat: NEAT, fitness: Callable[[Genomes], Tensor], task: Task, controller: Controller,
                        threshold: float | None, generations: int, *, episodes_per_genome: int,
                        validation_episodes: int = VALIDATION_EPISODES, test_episodes: int = TEST_EPISODES,
                        reporters: Iterable[BaseReporter] = ()) -> ThresholdRuns:
    """``ThresholdRuns(neat, ...).run(fitness, generations, ...)``: evolve, pick and test (module
    docstring); returns the ``ThresholdRuns`` (``records``, ``champions``)."""
    runs = ThresholdRuns(neat, task, controller, threshold, episodes_per_genome=episodes_per_genome,
                         validation_episodes=validation_episodes)
    runs.run(fitness, generations, reporters=reporters, test_episodes=test_episodes)
    return runs
