"""The double-pole study: NEAT-SNN and sigmoid NEAT on double-pole balancing as NEAT 2002 ran it.

Two variants (``VARIANTS``), each a ``DoublePoleTask`` through the public seam:

- ``"dpv"``: with velocities; fitness = control steps balanced from the standard start (long
  pole at 0.07 rad), up to 100,000; a run solves when a genome balances all 100,000.
  Population 150 ([NEAT02] Sec. 4.1).
- ``"dpnv"``: without velocities; fitness = Gruau et al.'s damping fitness over 1000 steps;
  a run solves when its champion of a generation balances 100,000 steps from the standard
  start and 200 or more of the 625 generalisation starts for 1000 steps ([NEAT02] Sec. 4.2,
  ``champion_solves``). Population 1000 ([NEAT02]).

A run's score is its evaluations to solve, ``generations x population`` as [NEAT02] counts
them (the champion tests are not counted, as there).

Observation scaling (the seam normalises to [0, 1] over symmetric bounds), the same for both
controllers: the failure limit for x (2.4 m), +-0.3 rad for the angles, +-2 m/s, +-2 rad/s and
+-4 rad/s for the velocities. Picked on tuning seeds 5000-5009 (``python -m
experiments.double_pole_tune``): with the task's default bounds (the 36 degree failure angle
for the poles) no sigmoid NEAT run balanced DPV beyond 426 steps in 40 generations, with ESP's
scaling none beyond 180; with these, runs balance 100,000 steps.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.phenotype import SPIKING_SIGMA, SigmoidSpec, SpikingSpec, network_inputs
from evolution.population import Genomes
from evolution.rollout import TaskFitness
from tasks.double_pole import DoublePoleTask
from tasks.studies.generalization import (
    GENERALIZATION_STEPS,
    GRUAU_RANGES,
    balanced_steps,
    generalization_starts,
)
from tasks.studies.neat121_runs import neat121_runs
from tasks.studies.registry import CONTROLLERS, STUDIES, ga_overrides

__all__ = ["LONG_BALANCE_STEPS", "GENERALIZATION_PASS", "GENERALIZATION_STARTS", "check_min_general", "champion_solves", "champions_pass", "champions_test", "SpeciesChampionTest", "species_champion_test", "VARIANTS", "CODINGS", "PUSH_PULL_INPUT_NA", "NEAT121_SCALES", "POPULATION", "OBSERVATION_BOUNDS", "PUBLISHED", "study_task", "study_spec", "study_config",
           "study_fitness", "study_solved", "damping_fitness_starts", "FITNESS_STARTS_SEED",
           "FITNESSES"]

VARIANTS = ("dpv", "dpnv")
# How observations reach the networks: "study": [0, 1] over OBSERVATION_BOUNDS (the study as first
# run); "signed": NEAT C++ 1.2.1's coding, each variable over its fixed scale, centred, unclipped
# (its cartpole2 experiment feeds x / 4.8, x_dot / 2, theta / 0.52, theta_dot / 2), signed input
# currents for NEAT-SNN (evolution.input_coding); "push-pull": the signed values on two input nodes
# per variable (the positive and the negative part), for NEAT-SNN at PUSH_PULL_INPUT_NA per unit.
CODINGS = ("study", "signed", "push-pull")
# NEAT-SNN's input current per unit of a push-pull input (nA). Picked on tuning seeds 5000-5004 (DPNV,
# 150 generations, docs/beyond-the-paper.md): one control step counts an input neuron's spikes over
# 20 ms, so at the study's 60 nA it reads an input to about 0.095 units (2.8 degrees of pole angle),
# too coarse to infer velocities; at 300 nA to about 0.019. 600 nA held fewer starts, 1200 none.
PUSH_PULL_INPUT_NA = 300.0
NEAT121_SCALES = {"dpv": (4.8, 2.0, 0.52, 2.0, 0.52, 2.0), "dpnv": (4.8, 0.52, 0.52)}  # m, m/s, rad, rad/s
POPULATION = {"dpv": 150, "dpnv": 1000}  # [NEAT02]
OBSERVATION_BOUNDS = {"dpv": (2.4, 2.0, 0.3, 2.0, 0.3, 4.0), "dpnv": (2.4, 0.3, 0.3)}  # m, m/s, rad, rad/s
LONG_BALANCE_STEPS = 100_000  # NEAT 2002: a champion must first balance this long from the standard start
GENERALIZATION_PASS = 200  # NEAT 2002: of the 625 generalisation starts, a DPNV solution balances this many
GENERALIZATION_STARTS = 625  # Gruau's grid: 5 fractions of each of 4 ranges (generalization_starts)
DPNV_EPISODE_STEPS = 1000  # Gruau's damping fitness is measured over 1000 steps
FITNESS_STARTS_SEED = 0  # the random starts of a multi-start DPNV fitness (damping_fitness_starts)
# The fitnesses a study evolves on: "study", the variant's own (DPV: steps balanced; DPNV: Gruau's
# damping fitness), or for DPNV "damping-both-poles", whose damping term also sums the short pole's
# angle and angular velocity. Picked for NEAT-SNN on tuning seeds 5010-5024 (docs/beyond-the-paper.md):
# its unsolved controllers' short pole rings under a chattering force, which Gruau's term cannot see.
FITNESSES = ("study", "damping-both-poles")

# Published figures, each with its source. ``evaluations``: mean evaluations to solve;
# ``generalization``: mean of the 625 starts balanced by the solutions; ``population``.
# [NEAT02] Stanley & Miikkulainen (2002), Evolutionary Computation 10(2), Tables 1 and 2.
# [CoSyNE08] Gomez, Schmidhuber & Miikkulainen (2008), JMLR 9, Table 2 (see docs/beyond-the-paper.md).
# "measured here": Stanley's NEAT C++ 1.2.1 built and run on this project's machine with its own
# parameter files (pole2_markov.ne, p2nv.ne), evaluations as it counts them (``neat121_*``:
# population x (generation - 1) + the winner's position), run by run in tasks/studies/neat121_runs.json
# (issue 29 first recorded 1016 and 131 runs, without the per-run figures: mean 3,605 and 30,770).
PUBLISHED: dict[str, list[dict]] = {
    "dpv": [
        {"method": "Ev. Programming", "evaluations": 307_200, "source": "NEAT02 Table 1"},
        {"method": "Conventional NE", "evaluations": 80_000, "source": "NEAT02 Table 1"},
        {"method": "SANE", "evaluations": 12_600, "source": "NEAT02 Table 1"},
        {"method": "ESP", "evaluations": 3_800, "source": "NEAT02 Table 1"},
        {"method": "NEAT", "evaluations": 3_600, "population": 150, "source": "NEAT02 Table 1"},
        neat121_runs("dpv").row(),
    ],
    "dpnv": [
        {"method": "Cellular Encoding", "evaluations": 840_000, "generalization": 300, "population": 16_384,
         "source": "NEAT02 Table 2"},
        {"method": "ESP", "evaluations": 169_466, "generalization": 289, "population": 1_000,
         "source": "NEAT02 Table 2"},
        {"method": "NEAT", "evaluations": 33_184, "generalization": 286, "population": 1_000,
         "source": "NEAT02 Table 2"},
        neat121_runs("dpnv").row(),
    ],
}


def _check(variant: str, controller: str | None = None, coding: str = "study") -> None:
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
    if coding not in CODINGS:
        raise ValueError(f"coding must be one of {CODINGS}, got {coding!r}")
    if controller is not None and controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")


def study_task(variant: str, coding: str = "study") -> DoublePoleTask:
    """The task a ``variant`` evolves on (its fitness, episode length and observation bounds:
    ``OBSERVATION_BOUNDS``, or NEAT 1.2.1's scales under the ``"signed"`` coding)."""
    _check(variant, coding=coding)
    bounds = (OBSERVATION_BOUNDS if coding == "study" else NEAT121_SCALES)[variant]
    if variant == "dpv":
        return DoublePoleTask.with_velocities(max_steps=LONG_BALANCE_STEPS, observation_bounds=bounds)
    return DoublePoleTask.without_velocities(fitness="damping", max_steps=DPNV_EPISODE_STEPS,
                                             observation_bounds=bounds)


def study_spec(variant: str, controller: str, coding: str = "study") -> SpikingSpec | SigmoidSpec:
    """The controller's coding (continuous force in +-10 N): sigmoid NEAT's defaults (NEAT 2002's
    steepened sigmoid, one update per control step); NEAT-SNN's defaults but with rates counted
    from rest (``rest_relative``) over one control step (20 ms, ``rate_window_steps=1``). Picked
    on tuning seeds 5000-5009 (docs/beyond-the-paper.md): without ``rest_relative`` no DPV run
    solved in 40 generations; with it, a window of 4 steps solved 4/10 by generation 40 and a
    window of 1 step 5/10 by generation 19. ``coding`` (``CODINGS``): ``"signed"`` and ``"push-pull"``
    feed NEAT 1.2.1's scaled values unclipped, on one input node per variable or two (push-pull:
    ``max(s, 0)`` and ``max(-s, 0)``, NEAT-SNN at ``PUSH_PULL_INPUT_NA`` nA per unit)."""
    _check(variant, controller, coding)
    spec = SpikingSpec(rest_relative=True, rate_window_steps=1) if controller == "snn" else SigmoidSpec()
    if coding == "study":
        return spec
    if coding == "signed":
        return replace(spec, input_coding="signed", clip_inputs=False)
    gain = {"i_input_max": PUSH_PULL_INPUT_NA} if controller == "snn" else {}
    return replace(spec, input_coding="push_pull", clip_inputs=False, **gain)


def study_config(variant: str, controller: str, *, self_loops: bool = False, ga: str = "tuned",
                 coding: str = "study", **overrides) -> NEATConfig:
    """The NEAT config of ``controller`` on ``variant`` under GA preset ``ga`` (default: the
    study's pick, ``STUDIES[variant].tuned_ga``): the population of [NEAT02], every input wired to the output at
    the start (plus a bias input for sigmoid NEAT), up to 16 hidden nodes. DPV's threshold is the
    100,000-step balance; DPNV has none (its runs solve by ``study_solved``)."""
    _check(variant, controller, coding)
    if ga == "tuned":
        ga, extra = STUDIES[variant].ga_choice(controller)
        overrides = {**extra, **overrides}
    task = study_task(variant, coding)
    base = dict(num_inputs=network_inputs(task, study_spec(variant, controller, coding)), num_outputs=1, pop_size=POPULATION[variant], max_hidden=16,
                initial_self_loops=self_loops,
                fitness_threshold=float(LONG_BALANCE_STEPS) if variant == "dpv" else math.inf)
    if controller == "snn":
        base.update(num_bias=0, **SPIKING_SIGMA)
    else:
        base.update(num_bias=1, sigma_mutate_rate=0.0, compatibility_sigma_coefficient=0.0)
    base.update(ga_overrides(ga))
    base.update(overrides)
    return NEATConfig(**base)


def damping_fitness_starts(task: DoublePoleTask, starts: int, seed: int = FITNESS_STARTS_SEED) -> Tensor:
    """The start states of a DPNV fitness over ``starts`` episodes, ``[starts, 107]`` float64 task
    states: the standard start (long pole at 0.07 rad) first, then ``starts - 1`` fixed random
    starts, the long pole's x (m), x_dot (m/s), theta1 (rad) and theta1_dot (rad/s) drawn
    uniformly within Gruau's ranges (``GRUAU_RANGES``, seeded by ``seed``), the short pole at
    rest. Not the generalisation test's grid, so the test still measures something the fitness
    did not see."""
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 1:
        raise ValueError(f"fitness_starts must be an int >= 1, got {starts!r}")
    plant = torch.zeros(starts, 6, dtype=torch.float64)
    plant[0] = task.reset(1)[0, :6]
    unit = torch.rand(starts - 1, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    plant[1:, :4] = (unit * 2 - 1) * torch.tensor(GRUAU_RANGES, dtype=torch.float64)
    return task.starts(plant)


def study_fitness(variant: str, controller: str, config: NEATConfig, coding: str = "study", *,
                  fitness_starts: int = 1, fitness: str = "study") -> TaskFitness:
    """``fitness_fn(genomes) -> [R, P]``: steps balanced (DPV) or the damping fitness (DPNV).
    ``fitness_starts`` (DPNV only): the mean damping fitness over that many episodes, from
    ``damping_fitness_starts`` (1: the standard start alone, NEAT 2002's fitness). ``fitness``
    (``FITNESSES``): ``"study"``, the variant's own, or (DPNV only) ``"damping-both-poles"``,
    Gruau's damping fitness with the short pole's angle and angular velocity in its damping term
    (``tasks.double_pole.DAMPING_TERMS``)."""
    _check(variant, controller, coding)
    if fitness not in FITNESSES:
        raise ValueError(f"fitness must be one of {FITNESSES}, got {fitness!r}")
    if fitness != "study" and variant != "dpnv":
        raise ValueError(f"fitness: only dpnv offers {fitness!r}, got it for {variant}")
    task, spec = study_task(variant, coding), study_spec(variant, controller, coding)
    if fitness != "study":
        task = task.with_fitness(fitness, DPNV_EPISODE_STEPS)
    if fitness_starts == 1:
        return TaskFitness(task, config, spec)
    if variant != "dpnv":
        raise ValueError(f"fitness_starts: only dpnv's damping fitness runs over several starts, got "
                         f"{fitness_starts!r} for {variant}")
    return TaskFitness(task, config, spec, episodes=fitness_starts, starts=damping_fitness_starts(task, fitness_starts))


def champion_solves(genomes, fitness: Tensor, config, spec=None, *, velocities: bool = False,
                    long_steps: int = LONG_BALANCE_STEPS, min_general: int = GENERALIZATION_PASS,
                    task: DoublePoleTask | None = None) -> Tensor:
    """NEAT 2002's test of a generation (a ``solved_fn`` for ``NEAT.run``): each run's champion (by
    ``fitness``) solves when it balances ``long_steps`` steps from the standard start and
    ``min_general`` or more of the 625 generalisation starts for 1000 steps. ``[R, P]`` bool,
    true at the solving champions."""
    best = fitness.argmax(-1, keepdim=True)  # [R, 1]
    solved = champions_pass(genomes.gather(best), config, spec, velocities=velocities, long_steps=long_steps,
                            min_general=min_general, task=task)
    out = torch.zeros(fitness.shape, dtype=torch.bool, device=fitness.device)
    return out.scatter(1, best, solved.unsqueeze(1))


def champions_pass(champions, config, spec=None, *, velocities: bool = False,
                   long_steps: int = LONG_BALANCE_STEPS, min_general: int = GENERALIZATION_PASS,
                   task: DoublePoleTask | None = None) -> Tensor:
    """NEAT 2002's test of one genome per run (``champions`` ``[R, 1]``): ``[R]`` bool, true where it
    balances ``long_steps`` steps from the standard start and ``min_general`` or more of the 625
    generalisation starts for 1000 steps (the 625 only for those that passed the first)."""
    return champions_test(champions, config, spec, velocities=velocities, long_steps=long_steps,
                          min_general=min_general, task=task)[0]


def champions_test(champions, config, spec=None, *, velocities: bool = False,
                   long_steps: int = LONG_BALANCE_STEPS, min_general: int = GENERALIZATION_PASS,
                   task: DoublePoleTask | None = None) -> tuple[Tensor, Tensor]:
    """``champions_pass`` with what it measured: ``(solved [R] bool, held [R] int64)``, ``held`` the
    generalisation starts each champion balances for 1000 steps (of 625), -1 where it was not
    run (the champion failed the long balance first)."""
    long = balanced_steps(champions, config, spec, velocities=velocities, max_steps=long_steps,
                          task=task)[:, 0, 0]
    solved = long >= long_steps
    held = torch.full_like(long, -1)
    if bool(solved.any()):  # the 625 starts only for the champions that held (each row's steps are its own)
        general = (balanced_steps(champions.select_runs(solved), config, spec, velocities=velocities,
                                  starts=generalization_starts(), task=task) >= GENERALIZATION_STEPS).sum(-1)[:, 0]
        held = held.masked_scatter(solved, general)
        solved = solved & (held >= min_general)
    return solved, held


class SpeciesChampionTest:
    """NEAT C++ 1.2.1's DPNV test of a generation (``pole2_epoch``), as a ``solved_fn(genomes, fitness)
    -> [R, P]`` of one ``NEAT``: in each unsolved run, one champion per generation is tested
    (``champions_pass``), the champion of the best species (by its best fitness this generation)
    that is not checked, or of the best species when every one is. Testing a species checks it; a
    species is unchecked again when its best fitness sets a record, above every earlier
    generation's best of it (``Species::max_fitness_ever``); a new species starts unchecked. The
    test of the overall champion (``champion_solves``) instead retests the same genome while it
    stays the best.

    The species' checks and records are state: ``state_dict()`` / ``load_state_dict()`` carry them
    through a checkpoint, so a resumed run tests what it would have.
    """

    def __init__(self, neat, test: Callable[[Genomes], Tensor]) -> None:
        self.neat, self.test = neat, test
        self.checked: list[dict[int, bool]] = [{} for _ in range(neat.num_runs)]
        self.record: list[dict[int, float]] = [{} for _ in range(neat.num_runs)]

    def _pick(self, r: int, slot: Tensor, f: Tensor) -> int:
        """Run ``r``'s genome to test this generation (its position), updating its species' checks
        and records; ``slot[P]`` the genomes' species slots, ``f[P]`` their fitness (float64)."""
        S = int(self.neat.species_state.ident.shape[1])
        best = torch.full((S,), -math.inf, dtype=torch.float64).scatter_reduce(0, slot, f, "amax")
        ident = self.neat.species_state.ident[r].cpu().tolist()
        present = sorted(set(slot.tolist()), key=lambda s: (-float(best[s]), s))  # the best species first
        checked, record = self.checked[r], self.record[r]
        for s in present:  # a record unchecks (a new species has none)
            if float(best[s]) > record.get(ident[s], -math.inf):
                checked[ident[s]] = False
        chosen = next((s for s in present if not checked.get(ident[s], False)), present[0])
        checked[ident[chosen]] = True
        for s in present:  # Species::adjust_fitness, after the test: max_fitness_ever
            record[ident[s]] = max(record.get(ident[s], -math.inf), float(best[s]))
        alive = {ident[s] for s in present}  # a species without members is gone for good
        self.checked[r] = {k: v for k, v in checked.items() if k in alive}
        self.record[r] = {k: v for k, v in record.items() if k in alive}
        return int(torch.nonzero((slot == chosen) & (f == best[chosen])).flatten()[0])

    def __call__(self, genomes: Genomes, fitness: Tensor) -> Tensor:
        neat = self.neat
        runs = torch.nonzero(neat.active_runs).flatten().tolist()  # the rows NEAT.solved_active passes
        if len(runs) != genomes.num_runs:
            raise ValueError(f"SpeciesChampionTest got {genomes.num_runs} runs, its NEAT has {len(runs)} unsolved")
        picks = torch.tensor([[self._pick(r, neat.species[r].cpu(), fitness[row].detach().cpu().to(torch.float64))]
                              for row, r in enumerate(runs)], dtype=torch.long).view(len(runs), 1)
        out = torch.zeros(fitness.shape, dtype=torch.bool, device=fitness.device)
        if len(runs):
            passed = self.test(genomes.gather(picks.to(genomes.device))).cpu()
            out = out.scatter(1, picks.to(out.device), passed.to(out.device).unsqueeze(1))
        return out

    def state_dict(self) -> dict:
        return {"checked": [{int(k): bool(v) for k, v in d.items()} for d in self.checked],
                "record": [{int(k): float(v) for k, v in d.items()} for d in self.record]}

    def load_state_dict(self, state: dict) -> None:
        R = self.neat.num_runs
        if isinstance(state, dict) and "tested" in state and "checked" not in state:
            raise ValueError("SpeciesChampionTest state is from the rule before 2026-12-06 (species 'tested' at a "
                             "fitness, not NEAT 1.2.1's checks and records): that run cannot resume bit for bit; "
                             "start it again")
        checked = state.get("checked") if isinstance(state, dict) else None
        record = state.get("record") if isinstance(state, dict) else None
        if not (isinstance(checked, list) and isinstance(record, list) and len(checked) == len(record) == R):
            raise ValueError(f"SpeciesChampionTest state must list {R} runs' checked species and records")
        self.checked = [{int(k): bool(v) for k, v in d.items()} for d in checked]
        self.record = [{int(k): float(v) for k, v in d.items()} for d in record]


def check_min_general(min_general: int) -> int:
    """``min_general`` if it is a count of the 625 generalisation starts (0-625), else a ``ValueError``
    naming the field."""
    if isinstance(min_general, bool) or not isinstance(min_general, int) or not 0 <= min_general <= GENERALIZATION_STARTS:
        raise ValueError(f"min_general must be an int of generalisation starts in 0..{GENERALIZATION_STARTS}, "
                         f"got {min_general!r}")
    return min_general


def species_champion_test(variant: str, controller: str, config: NEATConfig, neat,
                          coding: str = "study", *, min_general: int = GENERALIZATION_PASS) -> SpeciesChampionTest:
    """NEAT C++ 1.2.1's test of a DPNV generation for ``neat``'s runs (``SpeciesChampionTest``); a
    solution holds ``min_general`` of the 625 generalisation starts (NEAT 2002: 200)."""
    check_min_general(min_general)
    task, spec = study_task(variant, coding), study_spec(variant, controller, coding)
    return SpeciesChampionTest(neat, lambda champions: champions_pass(champions, config, spec,
                                                                      min_general=min_general, task=task))


def study_solved(variant: str, controller: str, config: NEATConfig, coding: str = "study", *,
                 champion_test: str = "champion", neat=None,
                 min_general: int = GENERALIZATION_PASS) -> Callable[[Genomes, Tensor], Tensor] | None:
    """NEAT 2002's test of a generation as a ``solved_fn(genomes, fitness) -> [R, P]``, or None
    where the fitness threshold decides (DPV: a genome balanced the whole 100,000 steps). DPNV,
    ``champion_test="champion"``: the overall champion of each generation; ``"species"``: NEAT
    C++ 1.2.1's choice of the champion to test, for ``neat``'s runs (``species_champion_test``).
    ``min_general``: the generalisation starts (of 625) a DPNV solution holds for 1000 steps besides
    the 100,000-step balance (NEAT 2002: 200, ``GENERALIZATION_PASS``); more asks for more general
    solutions, at the cost of evaluations."""
    _check(variant, controller, coding)
    check_min_general(min_general)
    if variant == "dpv":
        if min_general != GENERALIZATION_PASS:
            raise ValueError(f"min_general: only dpnv's test of a solution counts generalisation starts, got "
                             f"{min_general!r} for dpv")
        return None
    task, spec = study_task(variant, coding), study_spec(variant, controller, coding)
    if champion_test == "species":
        if neat is None:
            raise ValueError("the species champion test needs the NEAT whose runs it tests (neat=)")
        return species_champion_test(variant, controller, config, neat, coding, min_general=min_general)
    if champion_test != "champion":
        raise ValueError(f"champion_test must be 'champion' or 'species', got {champion_test!r}")

    def solved(genomes: Genomes, fitness: Tensor) -> Tensor:
        return champion_solves(genomes, fitness, config, spec, min_general=min_general, task=task)

    return solved
