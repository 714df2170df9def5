"""``snn-neat evolve ENV``: a controller evolved on any plant from the library's defaults, R runs
in one batch, resumable, optionally sharded over Ray.

What runs is what a Python user gets from the library:

    config = task_config(task, controller)           # pop_size, fitness_threshold: only where asked
    fitness = TaskFitness(task, config, controller, seed=seed)
    neat = NEAT(config, seeds=[seed, ..., seed + runs - 1])

with the task and threshold of ENV (``tasks.studies.env_task``), evolved to the threshold with
held-out checks and tested on 100 fresh episodes per run (``tasks.studies.threshold_runs``).
``seed`` in ``TaskFitness`` is ``--seed``, the first run's: one fitness serves the whole batch
(its episodes are seeded by it, and, where the library draws fresh starts, by each run's
population), so a run's results depend on its own seed and on ``--seed``, not on the other runs
in the batch or on how Ray splits them.

Budgets: ``--generations N`` per run, or ``--episodes N``, training episodes per run (genomes x
episodes per genome, per generation: the run stops before the generation that would spend more;
held-out and test episodes are counted apart).

Layout under ``OUT``: ``evolve.ckpt`` (the checkpoint of a local run: the NEAT state and every
run's records), or with ``--ray`` ``shards/evolve.json`` (the seeds and their split) and
``shards/evolve-K/evolve.ckpt`` (shard K's checkpoint). A Ray task always continues its shard's
checkpoint, so a retried task or a ``--resume`` (with or without ``--ray``) completes the rest.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from evolution.checkpoint import atomic_write_bytes
from evolution.config import NEATConfig
from evolution.neat import NEAT
from evolution.phenotype import task_config
from evolution.population import Genomes
from evolution.reporters import TqdmReporter
from evolution.rollout import TaskFitness
from tasks.studies.env_task import ResolvedEnv, resolve_env
from tasks.studies.registry import ReproduceError
from tasks.studies.resumable import RunCheckpoint, open_run
from tasks.studies.threshold_runs import RunRecord, ThresholdRuns

__all__ = ["CHECKPOINT", "DEFAULT_GENERATIONS", "EvolvePlan", "Built", "EnvRuns", "build", "evolve_seeds",
           "has_local_run", "has_shards", "run_plan"]

CHECKPOINT = "evolve.ckpt"
MANIFEST = Path("shards") / "evolve.json"
DEFAULT_GENERATIONS = 200


@dataclass(frozen=True)
class EvolvePlan:
    """What the command was asked (picklable: a Ray task rebuilds the run from it).

    Attributes:
        env: ENV as typed; controller: "snn" or "sigmoid"; seeds: every run's seed.
        generations, episodes: the budget per run (at most one; neither: ``DEFAULT_GENERATIONS``).
        pop_size: genomes per run (None: the library's); threshold: replaces ENV's (None: ENV's).
        device: torch device; checkpoint_every: generations between checkpoints (None: every 30 s).
    """

    env: str
    controller: str = "snn"
    seeds: tuple[int, ...] = (0,)
    generations: int | None = None
    episodes: int | None = None
    pop_size: int | None = None
    threshold: float | None = None
    device: str = "cpu"
    checkpoint_every: int | None = None


@dataclass
class Built:
    """The run the plan makes: ENV resolved, the config and fitness from the library's defaults,
    the threshold and where it came from, episodes per genome and the budget in generations."""

    resolved: ResolvedEnv
    config: NEATConfig
    fitness: TaskFitness
    threshold: float | None
    threshold_source: str
    episodes_per_genome: int
    generations: int

    def identity(self, plan: EvolvePlan, seeds: list[int]) -> dict:
        """What a checkpoint of these ``seeds`` must match to be resumed."""
        return {"command": "evolve", "env": plan.env, "controller": plan.controller, "seeds": list(seeds),
                "fitness_seed": plan.seeds[0], "generations": self.generations, "threshold": self.threshold,
                "episodes_per_genome": self.episodes_per_genome, "spec": repr(self.fitness.spec),
                "config": self.config.to_dict()}


def build(plan: EvolvePlan) -> Built:
    """ENV's task, and the config and fitness the library makes for it (module docstring)."""
    if plan.generations is not None and plan.episodes is not None:
        raise ReproduceError("give --generations or --episodes, not both")
    resolved = resolve_env(plan.env)
    if plan.threshold is not None:
        threshold, source = float(plan.threshold), "--threshold"
    else:
        threshold, source = resolved.threshold, resolved.threshold_source
    overrides: dict = {}
    if plan.pop_size is not None:
        overrides["pop_size"] = plan.pop_size
    if threshold is not None:
        overrides["fitness_threshold"] = threshold
    config = task_config(resolved.task, plan.controller, **overrides)
    fitness = TaskFitness(resolved.task, config, plan.controller, seed=plan.seeds[0])
    per_genome = int(getattr(fitness, "episodes", 1))
    generations = plan.generations or DEFAULT_GENERATIONS
    if plan.episodes is not None:
        per_generation = config.pop_size * per_genome
        generations = plan.episodes // per_generation
        if generations < 1:
            raise ReproduceError(f"--episodes {plan.episodes} is less than one generation ({config.pop_size} genomes "
                                 f"x {per_genome} episodes = {per_generation}): give at least {per_generation}")
    return Built(resolved, config, fitness, threshold, source, per_genome, generations)


@dataclass
class EnvRuns:
    """Every run's record and champion (``[R, 1]``), in seed order, the run's settings, the
    shards it ran in (0: one local batch) and the command's wall seconds (this process's)."""

    plan: EvolvePlan
    built: Built
    records: list[RunRecord]
    champions: Genomes
    shards: int = 1
    wall_s: float = 0.0


@dataclass
class _Part:
    """One batch's (a shard's) results, as plain data: what a Ray task returns."""

    records: list[dict]
    champions: dict[str, torch.Tensor]


def evolve_seeds(plan: EvolvePlan, seeds: list[int], folder: str | os.PathLike, *, resume: bool,
                 progress: bool = True, missing_ok: bool = False, stop_after: int | None = None) -> _Part | None:
    """Evolve (or continue) the runs of ``seeds`` as one batch, checkpointed in ``folder``;
    returns their records and champions (None when ``stop_after``, generations in this call
    for tests of interruption, stopped it first)."""
    built = build(plan)
    path = Path(folder) / CHECKPOINT
    identity = built.identity(plan, seeds)
    neat, data = open_run(path, identity, resume=resume, device=plan.device, missing_ok=missing_ok,
                          fresh=lambda: NEAT(built.config, seeds=seeds, device=plan.device))
    state = data.get("threshold_runs")
    if data and not isinstance(state, dict):
        raise ReproduceError(f"cannot resume {path}: it holds no records of `snn-neat evolve ENV`")
    runs = ThresholdRuns(neat, built.resolved.task, plan.controller, built.threshold,
                         episodes_per_genome=built.episodes_per_genome, state=state)
    reporters = [RunCheckpoint(path, identity, built.generations, every=plan.checkpoint_every,
                               records=lambda: {"threshold_runs": runs.state_dict()},
                               wall_s=float(data.get("wall_s", 0.0)))]
    bar = None
    if progress:
        bar = TqdmReporter(total=built.generations, initial=neat.generation, desc=f"{plan.env} {plan.controller}",
                           file=sys.stderr)
        reporters.insert(0, bar)
    try:
        champions = runs.run(built.fitness, built.generations, reporters=reporters, stop_after=stop_after)
    finally:
        if bar is not None:
            bar.end_run(None)  # closed now: a bar closed at exit would draw over an interruption's message
    if champions is None:
        return None
    return _Part([dict(vars(r)) for r in runs.records], {k: v.cpu() for k, v in champions.tensors().items()})


def has_local_run(out: str | os.PathLike) -> bool:
    return (Path(out) / CHECKPOINT).exists()


def has_shards(out: str | os.PathLike) -> bool:
    return (Path(out) / MANIFEST).exists()


def _layout(out: Path, seeds: list[int], shards: int | None, *, resume: bool) -> list[tuple[list[int], Path]]:
    """The shards under ``out``: the manifest's where one exists (which needs ``resume``), else
    ``shards`` new ones (the manifest is written)."""
    from tasks.studies.distributed import shard_seeds

    path = out / MANIFEST
    if has_local_run(out):
        raise ReproduceError(f"{out / CHECKPOINT} is the checkpoint of a local (unsharded) run: "
                             + ("resume it without --ray" if resume else "choose another --out"))
    if path.exists():
        if not resume:
            raise ReproduceError(f"{path} exists: pass --resume to continue it, or choose another --out")
        saved = json.loads(path.read_text())
        if saved.get("seeds") != seeds:
            raise ReproduceError(f"cannot resume {path}: it was written for seeds {saved.get('seeds')}, this call "
                                 f"asks for {seeds}")
        split = saved["shards"]
    else:
        if resume:
            raise ReproduceError(f"--resume: --out {str(out)!r} holds no checkpoint of `snn-neat evolve` "
                                 f"({CHECKPOINT} or {MANIFEST}): run without --resume to start")
        split = shard_seeds(seeds, shards or 1)
        atomic_write_bytes(path, json.dumps({"seeds": seeds, "shards": split}, indent=1).encode())
    return [(s, out / "shards" / f"evolve-{k}") for k, s in enumerate(split)]


def _shard(plan: EvolvePlan, seeds: list[int], folder: str, threads: int | None) -> _Part:
    """One shard, continuing its checkpoint where there is one: what a Ray task runs."""
    if threads is not None:
        torch.set_num_threads(threads)
    return evolve_seeds(plan, seeds, folder, resume=True, missing_ok=True, progress=False)


def _on_ray(plan: EvolvePlan, out: Path, address: str, *, resume: bool, progress: bool,
            max_retries: int = 3) -> list[_Part]:
    """Every shard as a Ray task on the cluster at ``address`` (one per cluster CPU, at most one
    per run); a task whose worker died is retried from its checkpoint. If the cluster goes away
    mid-run, a ``ReproduceError`` says so and ``--resume`` completes the rest."""
    import ray

    from tasks.studies.distributed import RayClusterLost, _abandon_ray, _connect, ray_results

    owned = not ray.is_initialized()
    gcs = _connect(address) if owned else None
    lost = False
    try:
        shards = max(1, int(ray.cluster_resources().get("CPU", 1)))
        layout = _layout(out, list(plan.seeds), shards, resume=resume)
        remote = ray.remote(_shard).options(num_cpus=1, num_gpus=1 if plan.device.startswith("cuda") else 0,
                                            max_retries=max_retries, retry_exceptions=False)
        refs = {remote.remote(plan, seeds, str(folder), 1): k for k, (seeds, folder) in enumerate(layout)}
        parts: dict[int, _Part] = {}
        try:
            for ref, value, exc in ray_results(refs, gcs):
                if exc is not None:
                    cause = getattr(exc, "cause", None)
                    if isinstance(cause, Exception):
                        raise cause from None
                    shard = f"shard {refs[ref] + 1}/{len(refs)}" if ref in refs else "a Ray task"
                    raise ReproduceError(f"--ray {address!r}: {shard} failed ({type(exc).__name__}: "
                                         f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
                parts[refs[ref]] = value
                if progress:
                    print(f"{plan.env} {plan.controller}: shard {refs[ref] + 1}/{len(refs)} finished "
                          f"[{len(parts)}/{len(refs)}]", file=sys.stderr, flush=True)
        except RayClusterLost:
            lost = True
            raise ReproduceError(f"--ray {address!r}: lost the Ray cluster mid-run ({len(parts)} of {len(refs)} "
                                 f"shards finished, checkpoints kept under {out / 'shards'}): run the same command "
                                 "with --resume to complete the rest") from None
        return [parts[k] for k in range(len(refs))]
    finally:
        if owned and lost:
            _abandon_ray()
        elif owned:
            ray.shutdown()


def run_plan(plan: EvolvePlan, out: str | os.PathLike, *, resume: bool = False, ray_address: str | None = None,
             progress: bool = True, built: Built | None = None) -> EnvRuns:
    """Run the plan into ``out``: one local batch (``OUT/evolve.ckpt``), the shards of a Ray run
    (``--ray``), or, resuming, the shards a Ray run left, here one after another. ``built``:
    ``build(plan)`` where the caller has it."""
    out = Path(out)
    t0 = time.perf_counter()
    built = built or build(plan)  # ENV's errors before any work
    seeds = list(plan.seeds)
    if ray_address is not None:
        parts = _on_ray(plan, out, ray_address, resume=resume, progress=progress)
    elif has_shards(out):
        parts = [evolve_seeds(plan, s, folder, resume=True, missing_ok=True, progress=progress)
                 for s, folder in _layout(out, seeds, None, resume=resume)]
    else:
        parts = [evolve_seeds(plan, seeds, out, resume=resume, progress=progress)]
    records = [RunRecord.from_dict(r) for p in parts for r in p.records]
    champions = Genomes(**{k: torch.cat([p.champions[k] for p in parts]) for k in parts[0].champions})
    sharded = ray_address is not None or has_shards(out)
    return EnvRuns(plan, built, records, champions, shards=len(parts) if sharded else 0,
                   wall_s=time.perf_counter() - t0)
