"""One rollout for every controller on every task: ``[R, P, episodes]`` as one batch.

``rollout(task, controller)`` runs each of the controller's ``G = R * P`` genomes for
``episodes`` episodes (row ``g * episodes + e``), one control step of the whole batch at a
time: observe, code as the controller's inputs (``evolution.input_coding``: by default [0, 1]
over the task's bounds), act (network state carried across control steps), step the plant. A row that terminates stops counting and its plant state is
frozen; when fewer than ``compact_below`` of the rows still in the batch are alive, the
finished ones are dropped (plant and controller state), so they stop costing compute. No
Python loop over genomes, episodes or neurons. Where the task has a native step and the
controller a C kernel, whole episodes run in one native call instead (``evolution.kernels.episodes``,
the same bits), and the loop here (traces, other controllers) steps the plant natively.

``TaskFitness`` turns a task into NEAT's ``fitness_fn(genomes) -> [R, P]``: the mean over
episodes of the return or the steps survived (``task.fitness``). Start states come from
``task.reset`` with a generator seeded by ``seed``: every genome, in every generation, faces
the same starts, so fitness is a pure function of the genome (resume after a kill stays exact);
or, with ``fresh_starts=True``, new starts each generation, seeded by the run's population.

Every operation is row-wise and every sum runs in slot order, so a genome's fitness does not
depend on its batch, its position, the compaction or which code path ran the network (C
kernel, compiled, torch: tested equal).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.defaults import RANDOM_START_EPISODES, has_random_starts
from evolution.input_coding import code_observations, coding_constants, input_coding_of
from evolution.kernels.episodes import native_rollout
from evolution.kernels.native_plant import native_plant
from evolution.phenotype import SigmoidSpec, SpikingSpec, as_spec, check_controller_config, make_controller
from evolution.population import Genomes
from evolution.task import Controller, Task, TaskError
from snn_torch.functional.scalars import scalar

__all__ = ["rollout", "RolloutResult", "TaskFitness", "evaluate", "episode_starts", "fresh_starts"]


@dataclass
class RolloutResult:
    """``returns [G, E]`` (float64, sum of rewards while alive), ``steps [G, E]`` (int64, control
    steps before the episode terminated, or all of them), ``terminated [G, E]`` (bool: the
    episode ended by the task's ``terminated``, at control step ``steps + 1``, not by the step
    limit) and, when recorded, ``trace``: per control step ``observation`` (before the step),
    ``action``, ``reward``, ``activity`` (spike counts or node values) and ``state`` (tensor
    states, after the step), each ``[T, G * E, ...]``; a finished row stays in the trace, frozen."""

    returns: Tensor
    steps: Tensor
    terminated: Tensor
    trace: dict[str, Tensor] | None = None

    def fitness(self, kind: str) -> Tensor:
        """``[G, E]`` float64: ``"return"`` or ``"steps"``."""
        return self.returns if kind == "return" else self.steps.to(torch.float64)


def _rebuild(like, parts):
    """A tuple state like ``like`` from its parts: a NamedTuple by its fields, a plain tuple as one."""
    return type(like)(*parts) if hasattr(like, "_fields") else tuple(parts)


def _rows(t, index: Tensor):
    if isinstance(t, Tensor):
        return t[index]
    return _rebuild(t, [x[index] for x in t])


def _where_rows(alive: Tensor, new, old):
    if isinstance(new, Tensor):
        return torch.where(alive.view(-1, *([1] * (new.dim() - 1))), new, old)
    return _rebuild(new, [_where_rows(alive, a, b) for a, b in zip(new, old, strict=True)])


def _float_parts(state) -> list[Tensor]:
    """The floating-point tensors of a state (a tensor, or a tuple of tensors)."""
    parts = [state] if isinstance(state, Tensor) else list(state)
    return [t for t in parts if isinstance(t, Tensor) and t.is_floating_point()]


def _describe(task: Task, rows: Tensor, bad: Tensor, episodes: int) -> str:
    idx = rows[torch.nonzero(bad).flatten()][:8].tolist()
    where = ", ".join(f"(genome {r // episodes}, episode {r % episodes})" for r in idx)
    return f"{int(bad.sum())} row(s), first: {where}"


def _check_batch(task: Task, method: str, field: str, value, rows: int, tail: tuple[int, ...] | None = None) -> None:
    if not isinstance(value, Tensor):
        raise TaskError(f"task {task.name!r}: {method} must return {field} as a tensor, got {type(value).__name__}")
    if value.shape[0] != rows or (tail is not None and tuple(value.shape[1:]) != tail):
        want = f"[{rows}{''.join(f', {d}' for d in tail)}]" if tail is not None else f"[{rows}, ...]"
        raise TaskError(f"task {task.name!r}: {method} returned {field} of shape {tuple(value.shape)}, expected {want}")


def _check_finite(task: Task, method: str, field: str, value: Tensor, alive: Tensor, rows: Tensor,
                  episodes: int) -> None:
    finite = torch.isfinite(value) if value.dim() == 1 else torch.isfinite(value.reshape(value.shape[0], -1)).all(-1)
    bad = alive & ~finite
    if bool(bad.any()):
        raise TaskError(f"task {task.name!r}: {method} returned {field} holding NaN or inf at "
                        f"{_describe(task, rows, bad, episodes)}")


def _check_starts(task: Task, starts, episodes: int, B: int) -> int:
    """The rows of ``starts`` (``episodes``: shared by every genome; ``B``: one per row), checked:
    shapes, and no NaN or inf in the starts themselves (before every genome gets a copy)."""
    parts = [starts] if isinstance(starts, Tensor) else list(starts)
    if not parts or not all(isinstance(part, Tensor) for part in parts):
        raise TaskError(f"task {task.name!r}: start states must be a tensor or a tuple of tensors")
    n_starts = parts[0].shape[0] if parts[0].dim() else -1
    if n_starts not in (episodes, B):
        raise TaskError(f"task {task.name!r}: start states have {n_starts} rows, expected {episodes} (one per "
                        f"episode, shared by every genome) or {B} (one per row)")
    for part in parts:
        _check_batch(task, "reset()", "state", part, n_starts)
    for part in _float_parts(starts):
        bad = ~torch.isfinite(part.reshape(n_starts, -1)).all(-1)
        if bool(bad.any()):
            first = torch.nonzero(bad).flatten()[:8].tolist()
            where = (", ".join(f"episode {e}" for e in first) if n_starts == episodes
                     else ", ".join(f"(genome {r // episodes}, episode {r % episodes})" for r in first))
            raise TaskError(f"task {task.name!r}: reset() returned state holding NaN or inf at {int(bad.sum())} of "
                            f"{n_starts} start(s), first: {where}")
    return n_starts


def episode_starts(task: Task, episodes: int, seed: int, *, device: torch.device | str = "cpu",
                   dtype: torch.dtype = torch.float32):
    """``task.reset(episodes, generator)`` with a generator seeded by ``seed``: the start states
    every genome is evaluated from."""
    generator = torch.Generator(device="cpu").manual_seed(int(seed))
    return task.reset(episodes, generator, device=device, dtype=dtype)


def fresh_starts(task: Task, genomes: Genomes, episodes: int, seed: int, *, device: torch.device | str = "cpu",
                 dtype: torch.dtype = torch.float32):
    """One start state per row of ``genomes`` x ``episodes`` (``[R * P * episodes, ...]``): every
    genome of run ``r`` starts from ``task.reset(episodes, generator)`` with a generator seeded by
    ``seed`` and the run population's ``fingerprint``. So each generation brings new starts (its
    population differs), the same ones again after a resume (it is restored bit for bit), and a
    run's starts do not depend on the other runs in the batch."""
    R, P = genomes.num_runs, genomes.pop_size
    per_run = [episode_starts(task, episodes, (key + int(seed) * 0x9E3779B97F4A7C15) % 2**64, device=device,
                              dtype=dtype) for key in genomes.fingerprint().tolist()]
    row = torch.arange(R * P * episodes, device=device)
    index = torch.div(row, P * episodes, rounding_mode="floor") * episodes + row % episodes
    if isinstance(per_run[0], Tensor):
        return torch.cat(per_run)[index]
    return _rebuild(per_run[0], [torch.cat(parts)[index] for parts in zip(*per_run, strict=True)])


def rollout(task: Task, controller: Controller, *, episodes: int = 1, seed: int = 0, starts=None, max_steps: int | None = None,
            record: bool = False, compact_below: float = 0.5, native: bool = True) -> RolloutResult:
    """Run every genome of ``controller`` on ``task`` for ``episodes`` episodes, as one batch.

    Args:
        task: an ``evolution.task.Task``.
        controller: any ``evolution.task.Controller`` over ``G`` genomes
            (``evolution.phenotype.make_controller`` makes NEAT-SNN's and sigmoid NEAT's).
        episodes: episodes per genome; starts: their start states, ``[episodes, ...]`` (as
            ``task.reset`` returns them) shared by every genome, or ``[G * episodes, ...]``, one
            per row (``fresh_starts``); default ``episode_starts(task, episodes, seed)``.
        max_steps: episode length (default ``task.max_steps``).
        record: keep a trace of every control step (no compaction; for plots).
        compact_below: drop finished rows when fewer than this fraction of the batch is alive.
        native: run whole episodes natively where possible (``evolution.kernels.episodes``; False: this
            Python loop, e.g. to compare: the results are the same bits).

    Returns:
        ``RolloutResult`` with ``[G, episodes]`` returns and steps.
    """
    task.validate()
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive int, got {episodes!r}")
    max_steps = task.max_steps if max_steps is None else max_steps
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 0:
        raise ValueError(f"max_steps must be a non-negative int, got {max_steps!r}")
    G = controller.num_genomes
    dtype, device = controller.dtype, controller.device
    if starts is None:
        starts = episode_starts(task, episodes, seed, device=device, dtype=dtype)
    B = G * episodes
    n_starts = _check_starts(task, starts, episodes, B)
    rows = torch.arange(B, device=device)  # original row of each batch row
    state = _rows(starts, rows % n_starts)
    alive = torch.ones(B, dtype=torch.bool, device=device)
    if native and not record:  # whole episodes natively where the task and controller allow (the same bits)
        ended = native_rollout(task, controller, starts, episodes=episodes, max_steps=max_steps)
        if ended is not None:
            returns, steps = ended
            return RolloutResult(returns.view(G, episodes), steps.view(G, episodes),
                                 (steps < max_steps).view(G, episodes))
    plant = native_plant(task, state.dtype) if isinstance(state, Tensor) else None
    if plant is not None and not plant.accepts(state):
        plant = None
    observe, step = (task.observe, task.step) if plant is None else (plant.observe, plant.step)
    cstate = controller.initial_state(torch.div(rows, episodes, rounding_mode="floor"))
    coding, clip = input_coding_of(controller)
    offset, scale = coding_constants(*task.bounds(device=device, dtype=dtype), coding)
    zero64 = scalar(0.0, offset.to(torch.float64))
    n_obs = task.observation_size
    returns = torch.zeros(B, dtype=torch.float64, device=device)
    steps = torch.zeros(B, dtype=torch.int64, device=device)
    batch_returns, batch_steps = returns, steps  # of the rows in the batch (all of them until compacted)
    trace: dict[str, list] | None = {"observation": [], "action": [], "reward": [], "activity": [], "state": []} \
        if record else None
    compacted, every_row_alive, n_rows = False, True, B
    for _ in range(max_steps):
        obs = observe(state)
        _check_batch(task, "observe()", "observation", obs, n_rows, (n_obs,))
        inputs = code_observations(obs if obs.dtype == dtype else obs.to(dtype), offset, scale, coding, clip)
        action, cstate, activity = controller.act(inputs, cstate)
        new_state, reward, terminated = step(state, action)
        _check_batch(task, "step()", "reward", reward, n_rows, ())
        _check_batch(task, "step()", "terminated", terminated, n_rows, ())
        if terminated.dtype != torch.bool:
            raise TaskError(f"task {task.name!r}: step() must return terminated as a bool tensor, got {terminated.dtype}")
        # One cheap test per step (a sum is finite unless some term is not, or it overflows); the
        # exact, row by row checks run only when it fails.
        new_parts = _float_parts(new_state)
        total = obs.sum() + reward.sum()
        for part in new_parts:
            total = total + part.sum()
        if not bool(torch.isfinite(total)):
            _check_finite(task, "observe()", "observation", obs, alive, rows, episodes)
            _check_finite(task, "step()", "reward", reward, alive, rows, episodes)
            for part in new_parts:  # the rows alive before this step: finished rows' states are not used
                if part.shape[0] == n_rows:
                    _check_finite(task, "step()", "state", part, alive, rows, episodes)
        if isinstance(new_state, Tensor) and new_state.shape[0] != n_rows:
            _check_batch(task, "step()", "state", new_state, n_rows)
        if every_row_alive:  # the usual case needs no masking (fewer ops per step)
            gained, still = reward.to(torch.float64), ~terminated
        else:
            gained, still = torch.where(alive, reward.to(torch.float64), zero64), alive & ~terminated
        batch_returns += gained
        batch_steps += still
        # a finished episode's plant is not simulated further
        state = new_state if every_row_alive else _where_rows(alive, new_state, state)
        alive = still
        if trace is not None:
            for key, value in (("observation", obs), ("action", action), ("reward", reward), ("activity", activity)):
                trace[key].append(value.detach().clone())
            if isinstance(state, Tensor):
                trace["state"].append(state.clone())
            if not bool(alive.any()):
                break
            every_row_alive = bool(alive.all())
            continue
        n_alive = int(alive.sum())
        if n_alive == 0:
            break
        every_row_alive = n_alive == n_rows
        if n_alive < compact_below * n_rows:
            keep = torch.nonzero(alive).flatten()
            cstate = controller.select(cstate, keep)
            if compacted:  # the dropped rows' totals are final: write the batch's back
                returns.index_copy_(0, rows, batch_returns)
                steps.index_copy_(0, rows, batch_steps)
            rows, state, alive = rows[keep], _rows(state, keep), alive[keep]
            batch_returns, batch_steps = batch_returns[keep], batch_steps[keep]
            compacted, every_row_alive, n_rows = True, True, n_alive
    if compacted:
        returns.index_copy_(0, rows, batch_returns)
        steps.index_copy_(0, rows, batch_steps)
    out = None
    if trace is not None:
        out = {k: torch.stack(v) for k, v in trace.items() if v}
    # A row survives a step unless it terminates in it, so it terminated iff it has fewer steps than the limit.
    ended = steps < max_steps
    return RolloutResult(returns.view(G, episodes), steps.view(G, episodes), ended.view(G, episodes), out)


class TaskFitness:
    """NEAT's ``fitness_fn(genomes) -> [R, P]`` for a task: the mean over ``episodes`` of each
    genome's return or steps survived (``task.fitness``).

    Args:
        task: the task; config: the NEAT config (inputs = observations, outputs = actions;
            ``task_config`` makes one), checked against the task and the controller here.
        spec: the controller: a ``SpikingSpec`` (NEAT-SNN) or ``SigmoidSpec`` (sigmoid NEAT), or
            the name of one (``"snn"``, the default, or ``"sigmoid"``) for the task's default spec
            (``evolution.defaults.default_spec``).
        episodes: episodes per genome; None (default): 16 fresh ones each generation on a task
            whose starts are random (``evolution.defaults.has_random_starts``), else 1.
        seed, starts, max_steps: as ``rollout``; backend: the spiking network's.
        fresh_starts: draw new start states each generation (``fresh_starts``: seeded by ``seed``
            and each run's population, so a resumed run sees the same ones) instead of the same
            ``episodes`` starts for every generation. None (default): on with the default episodes
            on a task whose starts are random, so the champions cannot learn a fixed few starts;
            off where the starts are the task (the paper's cart-poles), given, or ``episodes`` is.
    """

    def __init__(self, task: Task, config: NEATConfig, spec: SpikingSpec | SigmoidSpec | str | None = None, *,
                 episodes: int | None = None, seed: int = 0, starts=None, max_steps: int | None = None,
                 backend: str = "auto", fresh_starts: bool | None = None) -> None:
        self.task, self.config, self.spec = task.validate(), config, as_spec(spec, task)
        check_controller_config(config, task, self.spec)
        if fresh_starts and starts is not None:
            raise ValueError("TaskFitness takes fixed starts= or fresh_starts=True, not both")
        if episodes is None:  # the defaults: 16 fresh episodes a generation where the starts are random
            random_starts = starts is None and has_random_starts(task)
            episodes = RANDOM_START_EPISODES if random_starts else 1
            fresh_starts = random_starts if fresh_starts is None else fresh_starts
        self.episodes, self.seed, self.starts, self.max_steps, self.backend = episodes, seed, starts, max_steps, backend
        self.fresh_starts = bool(fresh_starts)

    def rollout(self, genomes: Genomes, *, record: bool = False) -> RolloutResult:
        controller = make_controller(genomes, self.config, self.task, self.spec, backend=self.backend)
        starts = self.starts
        if self.fresh_starts:
            starts = fresh_starts(self.task, genomes, self.episodes, self.seed, device=controller.device,
                                  dtype=controller.dtype)
        return rollout(self.task, controller, episodes=self.episodes, seed=self.seed, starts=starts,
                       max_steps=self.max_steps, record=record)

    def __call__(self, genomes: Genomes) -> Tensor:
        result = self.rollout(genomes)
        return result.fitness(self.task.fitness).mean(-1).view(genomes.num_runs, genomes.pop_size)


def evaluate(task: Task, genomes: Genomes, config: NEATConfig, spec: SpikingSpec | SigmoidSpec | str | None = None,
             **kwargs) -> Tensor:
    """``TaskFitness(task, config, spec, **kwargs)(genomes)``: ``[R, P]`` fitness."""
    return TaskFitness(task, config, spec, **kwargs)(genomes)
