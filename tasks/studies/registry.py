"""The studies ``snn-neat reproduce`` runs, one entry each: ``STUDIES[name] -> Study``.

A study is a plant task, each controller's spec (coding) and NEAT config, the fitness, the test
that says a run solved it, the GA each controller was tuned to, and the report that writes its
results. Adding a study is one entry here and a module implementing five functions of the study's
name (``study_task``, ``study_spec``, ``study_config``, ``study_fitness``, ``study_solved``; see
``tasks/studies/double_pole.py``): the CLI's choices, its memory check, the run loop
(``tasks.studies.reproduce``) and the report all read the entry.

This module imports nothing but the standard library, so the CLI's ``--help`` needs no torch; the
study's own module is imported when the study is first used.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["CONTROLLERS", "GA_PRESETS", "GA_CHOICES", "Study", "STUDIES", "ReproduceError", "describe_ga", "ga_overrides",
           "study"]

CONTROLLERS = ("snn", "sigmoid")

class _GAPresets(Mapping):
    """GA settings, as named presets over NEATConfig (name -> overrides).

    "neat-c++": NEATConfig's defaults ([NEAT02], [Qiu19], and NEAT C++'s weight mutation).
    "neat-python": neat-python 2.0.0's defaults wherever they differ and this NEAT has the knob
    (per-gene weight mutation of power 0.5 within +-30, its 2 best genomes of every species
    kept, crossover for every child, no interspecies mating, stagnation after 20 generations,
    distance weight term 0.5 and genes counted by the larger genome at any size); neat-python's
    node bias genes are this NEAT's bias-input connections. "neat-1.2.1-dpv" and
    "neat-1.2.1-dpnv": NEAT C++ 1.2.1's own parameter files for double-pole balancing
    (``pole2_markov.ne``, ``p2nv.ne``; ``evolution.neat121``, with their populations of 150 and
    1000), loaded on first use: that module needs torch, and this one must not.
    "neat-1.2.1-dpnv-per-gene": ``p2nv.ne`` with population 300 and per-gene weight steps, the
    project's DPNV pick on tuning seeds (``evolution.neat121.NEAT121_DPNV_PER_GENE``).
    "neat-1.2.1-dpnv-snn": the same with population 100, NEAT-SNN's DPNV pick on tuning seeds
    (``evolution.neat121.NEAT121_DPNV_SNN``).
    """

    _OWN = {
        "neat-c++": {},
        "neat-python": dict(
            weight_mutate_power=0.5, weight_mutate_per_gene=True, weight_max_value=30.0, weight_min_value=-30.0,
            elitism=2, elitism_min_species_size=1, crossover_prob=1.0, interspecies_crossover_prob=0.0,
            max_stagnation=20, compatibility_weight_coefficient=0.5, compatibility_normalize_min_genes=1),
    }
    _NEAT121 = {"neat-1.2.1-dpv": "NEAT121_DPV", "neat-1.2.1-dpnv": "NEAT121_DPNV",
                "neat-1.2.1-dpnv-per-gene": "NEAT121_DPNV_PER_GENE", "neat-1.2.1-dpnv-snn": "NEAT121_DPNV_SNN"}

    def __getitem__(self, name: str) -> Mapping:
        if name in self._OWN:
            return MappingProxyType(self._OWN[name])
        if name in self._NEAT121:
            return MappingProxyType(getattr(importlib.import_module("evolution.neat121"), self._NEAT121[name]))
        raise KeyError(name)

    def __iter__(self):
        return iter([*self._OWN, *self._NEAT121])

    def __len__(self) -> int:
        return len(self._OWN) + len(self._NEAT121)


GA_PRESETS: Mapping[str, Mapping] = _GAPresets()
GA_CHOICES = ("tuned", *GA_PRESETS)


class ReproduceError(ValueError):
    """A study cannot start or resume as asked: a study, controller, GA, coding or champion test that
    does not exist, or a checkpoint that does not match (the message names the option)."""


def ga_overrides(ga: str) -> dict:
    """The ``NEATConfig`` fields a GA preset sets (``GA_PRESETS``)."""
    if ga not in GA_PRESETS:
        raise ReproduceError(f"ga must be one of {tuple(GA_PRESETS)}, got {ga!r}")
    return dict(GA_PRESETS[ga])


def describe_ga(preset: str, extra: Mapping) -> str:
    """``"neat-python, survival_threshold=0.1"``: a GA choice in words, for tables and checkpoints."""
    return ", ".join([preset, *(f"{k}={v:g}" for k, v in sorted(extra.items()))])


def _only_for(attribute: str, common: str) -> str:
    """`` ('X' only for a, b)`` for each choice of the studies' ``attribute`` but ``common``."""
    offered = {c: [s.name for s in STUDIES.values() if c in getattr(s, attribute)]
               for s in STUDIES.values() for c in getattr(s, attribute) if c != common}
    return "".join(f" ({c!r} only for {', '.join(names)})" for c, names in offered.items())


@dataclass(frozen=True)
class Study:
    """One study of ``snn-neat reproduce``.

    Attributes:
        name: the CLI's name (``snn-neat reproduce NAME``).
        description: what it is, one sentence.
        module: the module implementing ``study_task(name, coding)``, ``study_spec(name, controller,
            coding)``, ``study_config(name, controller, *, self_loops, ga, coding, **overrides)`` (``ga``:
            a preset of ``GA_PRESETS``), ``study_fitness(name, controller, config, coding)`` (with
            ``fitness_starts=K`` where it offers ``multi_start_fitness``, ``fitness=NAME`` where it
            offers more than one of ``fitnesses``) and
            ``study_solved(name, controller, config, coding, *, neat=None)`` (None where the config's
            fitness threshold decides).
        tuned_ga: each controller's GA (``--ga tuned``): ``(preset, extra NEATConfig overrides)``.
        report: ``"module:function"`` writing the report, ``f(results, name, out, *, command,
            generalization)``.
        codings: the input codings it offers (``--coding``); the first is the study's own.
        champion_tests: the tests of a generation it offers (``--champion-test``); the first is the default.
        multi_start_fitness: whether its fitness can run over several starts (``--fitness-starts``;
            ``study_fitness(..., fitness_starts=K)``); otherwise only the one start of its own.
        fitnesses: the fitnesses it evolves on (``--fitness``); the first, ``"study"``, is its own.
        general_solutions: whether its test of a solution counts generalisation starts (``--min-general``;
            ``study_solved(..., min_general=N)``, the module's ``GENERALIZATION_PASS`` by default).
    """

    name: str
    description: str
    module: str
    tuned_ga: Mapping[str, tuple[str, Mapping]]
    report: str
    codings: tuple[str, ...] = ("study", "signed")
    champion_tests: tuple[str, ...] = ("champion",)
    multi_start_fitness: bool = False
    fitnesses: tuple[str, ...] = ("study",)
    general_solutions: bool = False
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def _impl(self):
        if "module" not in self._cache:
            self._cache["module"] = importlib.import_module(self.module)
        return self._cache["module"]

    def check(self, controller: str, coding: str = "study", champion_test: str | None = None,
              fitness_starts: int = 1, fitness: str = "study") -> str:
        """``ReproduceError`` naming the option the study does not offer; returns the champion test
        (``champion_test``, or the study's default: its first)."""
        if isinstance(fitness_starts, bool) or not isinstance(fitness_starts, int) or fitness_starts < 1:
            raise ReproduceError(f"fitness_starts must be an int >= 1, got {fitness_starts!r}")
        if fitness_starts != 1 and not self.multi_start_fitness:
            offered = [s.name for s in STUDIES.values() if s.multi_start_fitness]
            raise ReproduceError(f"fitness_starts must be 1 for {self.name} (a fitness over several starts only for "
                                 f"{', '.join(offered)}), got {fitness_starts!r}")
        if fitness not in self.fitnesses:
            raise ReproduceError(f"fitness must be one of {self.fitnesses}{_only_for('fitnesses', 'study')}, "
                                 f"got {fitness!r} for {self.name}")
        champion_test = self.champion_tests[0] if champion_test is None else champion_test
        if controller not in CONTROLLERS:
            raise ReproduceError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
        if coding not in self.codings:
            raise ReproduceError(f"coding must be one of {self.codings} for {self.name}, got {coding!r}")
        if champion_test not in self.champion_tests:
            raise ReproduceError(f"champion_test must be one of {self.champion_tests}"
                                 f"{_only_for('champion_tests', 'champion')}, got {champion_test!r} for {self.name}")
        return champion_test

    def min_general(self, min_general: int | None) -> int | None:
        """``min_general`` checked (``ReproduceError`` naming the field), None for the study's own
        (None, or the value it uses by default), so a checkpoint's identity holds one spelling."""
        if min_general is None:
            return None
        if not self.general_solutions:
            offered = [s.name for s in STUDIES.values() if s.general_solutions]
            raise ReproduceError(f"min_general: only {', '.join(offered)} count generalisation starts in the test "
                                 f"of a solution, got {min_general!r} for {self.name}")
        try:
            self._impl().check_min_general(min_general)
        except ValueError as exc:
            raise ReproduceError(str(exc)) from None
        return None if min_general == self._impl().GENERALIZATION_PASS else min_general

    def ga_choice(self, controller: str, ga: str = "tuned") -> tuple[str, dict]:
        """``(preset, extra overrides)`` for ``ga``: a preset as it is, or ``"tuned"``: the controller's pick."""
        self.check(controller)
        if ga == "tuned":
            preset, extra = self.tuned_ga[controller]
            return preset, dict(extra)
        if ga not in GA_PRESETS:
            raise ReproduceError(f"ga must be one of {GA_CHOICES}, got {ga!r}")
        return ga, {}

    def task(self, coding: str = "study"):
        """The plant task its runs evolve on (``evolution.task.Task``)."""
        if coding not in self.codings:
            raise ReproduceError(f"coding must be one of {self.codings} for {self.name}, got {coding!r}")
        return self._impl().study_task(self.name, coding)

    def spec(self, controller: str, coding: str = "study"):
        """The controller's spec (``SpikingSpec`` or ``SigmoidSpec``) under ``coding``."""
        self.check(controller, coding)
        return self._impl().study_spec(self.name, controller, coding)

    def config(self, controller: str, *, self_loops: bool = False, ga: str = "tuned", coding: str = "study",
               **overrides):
        """The ``NEATConfig`` ``controller`` evolves with (the CLI's memory check reads it too)."""
        self.check(controller, coding)
        preset, extra = self.ga_choice(controller, ga)
        return self._impl().study_config(self.name, controller, self_loops=self_loops, ga=preset, coding=coding,
                                         **{**extra, **overrides})

    def fitness(self, controller: str, config, coding: str = "study", fitness_starts: int = 1,
                fitness: str = "study"):
        """``fitness_fn(genomes) -> [R, P]``; ``fitness_starts``: episodes per evaluation, where the
        study offers it (``multi_start_fitness``); ``fitness``: one of its ``fitnesses``."""
        self.check(controller, coding, fitness_starts=fitness_starts, fitness=fitness)
        extra = {} if fitness_starts == 1 else {"fitness_starts": fitness_starts}
        if fitness != "study":
            extra["fitness"] = fitness
        return self._impl().study_fitness(self.name, controller, config, coding, **extra)

    def solved(self, controller: str, config, coding: str = "study", *, champion_test: str | None = None,
               neat=None, min_general: int | None = None):
        """``solved_fn(genomes, fitness) -> [R, P]`` bool, or None where the config's fitness threshold
        decides. ``champion_test``: one the study offers (default: its first); a test that keeps
        a record per run (DPNV's ``"species"``) needs the ``neat`` whose runs it tests.
        ``min_general``: the generalisation starts a solution holds, where the study counts them
        (``general_solutions``; None: the study's own)."""
        champion_test = self.check(controller, coding, champion_test)
        extra = {} if self.min_general(min_general) is None else {"min_general": min_general}
        return self._impl().study_solved(self.name, controller, config, coding, champion_test=champion_test,
                                         neat=neat, **extra)

    def write_report(self, results: dict, out, *, command: str, generalization: bool = True) -> list:
        """Write the study's report of ``results`` (controller -> ``ControllerRuns``) to ``out``."""
        module, function = self.report.split(":")
        return getattr(importlib.import_module(module), function)(results, self.name, out, command=command,
                                                                  generalization=generalization)


# Each controller's GA settings per study, as used by ``snn-neat reproduce`` (``--ga tuned``):
# picked by ``python -m experiments.tune_ga`` on tuning seeds 5000-5059 (5000-5031 for NEAT-SNN
# on Table I), never on a reported seed set, from the same grid for every controller: both
# presets x survival threshold 0.1 or 0.2 ([Qiu19]'s); for NEAT-SNN on Table I only the neat-c++
# preset (its 100,000-step spiking episodes made the neat-python runs too costly). The numbers
# behind each pick are in docs/reproducing.md ("GA settings, chosen per controller"). Table II
# was re-tuned under the counter-based streams (NEAT-SNN: survival 0.1 -> 0.2, mean 12.35 ->
# 11.08; sigmoid NEAT unchanged); Table I's picks date from the earlier mt19937 streams.
_NEAT_PYTHON_01 = ("neat-python", MappingProxyType({"survival_threshold": 0.1}))
_NEAT_CPP = ("neat-c++", MappingProxyType({}))
_PAPER_REPORT = "tasks.studies.table_report:write_table_report"
_DOUBLE_POLE_REPORT = "tasks.studies.double_pole_report:write_study_report"
_DOUBLE_POLE_CODINGS = ("study", "signed", "push-pull")  # tasks.studies.double_pole.CODINGS (tested equal)
_DPNV_FITNESSES = ("study", "damping-both-poles")  # tasks.studies.double_pole.FITNESSES (tested equal)

STUDIES: Mapping[str, Study] = MappingProxyType({s.name: s for s in (
    Study("table1", "Markov cart-pole (Table I): x, x_dot, theta, theta_dot as Bernoulli-coded input spikes, "
          "bang-bang +-10 N, tau 20 ms, success at 100,000 steps", "tasks.studies.cartpole",
          {"sigmoid": _NEAT_PYTHON_01, "snn": _NEAT_CPP}, _PAPER_REPORT),
    Study("table2", "non-Markov cart-pole (Table II): x and theta only, continuous force, tau 10 ms, start at "
          "3 degrees, success at 5000 steps", "tasks.studies.cartpole",
          {"sigmoid": _NEAT_PYTHON_01, "snn": _NEAT_CPP}, _PAPER_REPORT),
    # double pole (tasks.studies.double_pole): picked on tuning seeds 5000-5009, 40 generations of
    # DPV; DPNV takes DPV's pick (docs/beyond-the-paper.md)
    Study("dpv", "double-pole balancing with velocities (NEAT 2002): six inputs, +-10 N, population 150, "
          "solved when a genome balances 100,000 steps", "tasks.studies.double_pole",
          {"sigmoid": _NEAT_PYTHON_01, "snn": _NEAT_PYTHON_01}, _DOUBLE_POLE_REPORT,
          codings=_DOUBLE_POLE_CODINGS),
    # DPNV's test of a generation: NEAT C++ 1.2.1's ("species": the champion of the best species not
    # tested since its last record, the best when all were), or each generation's overall champion ("champion", the default
    # before 2026-12-03, which retests the same genome while it stays the best); its damping fitness
    # can be the mean over several starts (--fitness-starts, docs/beyond-the-paper.md) and see the short
    # pole (--fitness damping-both-poles)
    Study("dpnv", "double-pole balancing without velocities (NEAT 2002): x and both angles, Gruau's damping "
          "fitness over 1000 steps, population 1000, solved when a champion balances 100,000 steps and 200 of "
          "the 625 generalisation starts", "tasks.studies.double_pole",
          {"sigmoid": _NEAT_PYTHON_01, "snn": _NEAT_PYTHON_01}, _DOUBLE_POLE_REPORT,
          codings=_DOUBLE_POLE_CODINGS, champion_tests=("species", "champion"), multi_start_fitness=True,
          fitnesses=_DPNV_FITNESSES, general_solutions=True),
)})


def study(name: str) -> Study:
    """``STUDIES[name]``, or a ``ReproduceError`` naming the choices."""
    if name not in STUDIES:
        raise ReproduceError(f"table must be one of {tuple(STUDIES)}, got {name!r}")
    return STUDIES[name]
