"""The NEAT driver: ask/tell, ``run``, reporters, checkpoints.

Many independent runs evolve in one batch (``seeds``, one per run). A run that reaches the
fitness target is frozen: it is neither reproduced nor does it draw random numbers any more,
so each run's history is exactly what it would be alone.

    neat = NEAT(NEATConfig(num_inputs=2, num_outputs=1), seeds=range(8))
    neat.add_reporter(StdOutReporter())
    result = neat.run(fitness_fn, generations=100, fitness_target=3.9)

``fitness_fn(genomes) -> Tensor[R, P]`` must return finite values; higher is better.
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import Tensor

from evolution.checkpoint import (
    CHECKPOINT_FORMAT,
    CHECKPOINT_VERSION,
    CheckpointError,
    atomic_torch_save,
    load_checkpoint_dict,
)
from evolution.config import ConfigError, NEATConfig
from evolution.kernels import breed as breed_kernel
from evolution.population import Genomes, InvariantError, check_invariants, initial_genomes
from evolution.reporters import BaseReporter, GenerationStatus
from evolution.reproduce import ReproductionInfo, reproduce
from evolution.rng import RunRNG
from evolution.speciate import SpeciesState, empty_species, speciate
from snn_torch._malloc import keep_freed_memory

__all__ = ["NEAT", "NEATResult", "FitnessError"]


def _genome_fields(dtype: torch.dtype, N: int, mutation_num: bool = False) -> list[tuple[str, tuple[int, ...], torch.dtype]]:
    """(field, shape after the [R, K] axes, dtype) of each ``Genomes`` tensor (``mutation_num``
    where the config carries it)."""
    return [("weight", (N, N), dtype), ("conn", (N, N), torch.bool), ("enabled", (N, N), torch.bool),
            ("node", (N,), torch.bool), ("sigma", (), dtype)] + ([("mutation_num", (N, N), dtype)] if mutation_num else [])

FitnessFn = Callable[[Genomes], Tensor]


class FitnessError(ValueError):
    """The fitness function returned a wrong shape, or NaN/inf for some genomes."""


@dataclass
class NEATResult:
    """Outcome per run. ``solved_generation[r]``: how many generations run ``r`` had
    evaluated when a genome first reached the target (1 = the initial population), or -1."""

    best_fitness: Tensor  # [R] float64
    best_genomes: Genomes  # [R, 1]
    solved_generation: Tensor  # [R] long
    generations: int
    # [R] long: the index of the first solving genome in that generation (-1: not solved, or not
    # recorded); NEAT C++ 1.2.1 counts evaluations as pop_size * (generation - 1) + index + 1.
    solved_position: Tensor | None = None


class NEAT:
    """Tensor NEAT over ``R = len(seeds)`` independent runs of ``config.pop_size`` genomes.

    ``reproduce_chunk_genomes``: reproduction handles the runs in chunks of about this many
    genomes (at least one run); it changes speed and memory, never a result.
    """

    reproduce_chunk_genomes: int = 12_000
    #: Breed and speciate with the C kernels (True), the tensor operators (False), or the
    #: kernels wherever they can run (None). The same result either way (tested).
    fused_breeding: bool | None = None

    def __init__(self, config: NEATConfig, *, seeds: Iterable[int] = (0,), device: str | torch.device = "cpu",
                 dtype: torch.dtype = torch.float32) -> None:
        if not isinstance(config, NEATConfig):
            raise ConfigError(f"config must be a NEATConfig, got {type(config).__name__}")
        keep_freed_memory()  # the children's tensors of each generation reuse the last ones' memory
        self.config = config
        self.rng = RunRNG(_seed_list(seeds), device)
        self.dtype = dtype
        self.generation = 0
        self.fitness_target = config.fitness_threshold
        self.reporters: list[BaseReporter] = []
        self.last_status: GenerationStatus | None = None  # what the reporters saw of the last generation
        self._extinct_now: list[int] = []
        self.genomes = initial_genomes(config, self.rng, dtype=dtype)
        R = self.num_runs
        state = empty_species(R, config.num_nodes, 4, device=self.rng.device, dtype=dtype)
        self.species, self.species_state = speciate(self.genomes, state, config, self.rng, 0)
        self.best_fitness = torch.full((R,), -torch.inf, dtype=torch.float64, device=self.rng.device)
        self.best_genomes = self.genomes.gather(torch.zeros(R, 1, dtype=torch.long, device=self.rng.device))
        self.solved_generation = torch.full((R,), -1, dtype=torch.long, device=self.rng.device)
        self.solved_position = torch.full((R,), -1, dtype=torch.long, device=self.rng.device)

    # --- basics ------------------------------------------------------------------------
    @property
    def num_runs(self) -> int:
        return len(self.rng)

    @property
    def device(self) -> torch.device:
        return self.rng.device

    @property
    def active_runs(self) -> Tensor:
        """Runs still evolving (not yet solved), ``[R]`` bool."""
        return self.solved_generation < 0

    def add_reporter(self, reporter: BaseReporter) -> BaseReporter:
        self.reporters.append(reporter)
        return reporter

    def _report(self, hook: str, arg) -> None:
        for r in self.reporters:
            getattr(r, hook)(arg)

    # --- ask / tell --------------------------------------------------------------------
    def ask(self) -> Genomes:
        """The population to evaluate, ``[R, P]``."""
        return self.genomes

    def tell(self, fitness: Tensor, solved: Tensor | None = None) -> None:
        """Take the fitness of ``ask()``'s genomes and breed the next generation.

        ``solved[R, P]`` (bool) says which genomes solve the task; by default those with
        fitness >= ``fitness_target``.
        """
        fitness = self._check_fitness(fitness)
        R = self.num_runs
        runs = torch.arange(R, device=self.device)
        active = self.active_runs
        if solved is None:
            solved = fitness >= self.fitness_target
        elif tuple(solved.shape) != tuple(fitness.shape) or solved.dtype != torch.bool:
            raise FitnessError(f"solved must be a bool tensor of shape {tuple(fitness.shape)}")
        solved = solved.to(self.device)
        newly = active & solved.any(1)
        # The run's champion: the fittest genome, or for a run that just solved, the
        # fittest genome among those that solve.
        best_f, best_i = torch.where(newly.unsqueeze(1) & ~solved, -torch.inf, fitness).max(1)
        better = active & ((best_f > self.best_fitness) | newly)
        champions = self.genomes.gather(best_i.unsqueeze(1))
        self.best_genomes = self.best_genomes.where(better.unsqueeze(1), champions)
        self.best_fitness = torch.where(better, best_f, self.best_fitness)
        self.solved_generation = torch.where(newly, self.generation + 1, self.solved_generation)
        first = solved.to(torch.int8).argmax(1)  # the first maximal index: the first solving genome
        self.solved_position = torch.where(newly, first, self.solved_position)
        # What reporters see of the evaluated population, taken before breeding overwrites it
        # (only when some reporter listens).
        seen = self._evaluated() if self.reporters else None
        self._extinct_now = []
        evolving = runs[self.active_runs].tolist()
        info = self._reproduce(fitness, evolving) if evolving else None
        self.generation += 1
        if seen is not None:
            refused = torch.zeros(R, dtype=torch.long)
            offspring = torch.zeros(R, 0 if info is None else info.offspring.shape[1], dtype=torch.long)
            if info is not None:
                refused[evolving] = info.split_refused.cpu().to(torch.long)
                offspring[evolving] = info.offspring.cpu().to(torch.long)
            status = GenerationStatus(generation=self.generation - 1, fitness=fitness, best_fitness=self.best_fitness,
                                      solved_generation=self.solved_generation, newly_solved=runs[newly].tolist(),
                                      extinct=self._extinct_now, split_refused=refused, offspring=offspring,
                                      state_dict=self.state_dict,
                                      **seen)
            self.last_status = status
            if status.newly_solved:
                self._report("found_solution", status)
            if status.extinct:
                self._report("complete_extinction", status)
            self._report("end_generation", status)

    def _evaluated(self) -> dict[str, Tensor]:
        """The evaluated population's genes, hidden nodes and species, for ``GenerationStatus``."""
        return {"genes": self.genomes.num_genes(), "hidden": self.genomes.num_hidden(self.config),
                "species": self.species.clone(), "species_ident": self.species_state.ident.clone(),
                "species_alive": self.species_state.alive.clone()}

    def _check_fitness(self, fitness: Tensor) -> Tensor:
        R, P = self.num_runs, self.config.pop_size
        if not isinstance(fitness, Tensor):
            raise FitnessError(f"fitness must be a tensor of shape [{R}, {P}], got {type(fitness).__name__}")
        if tuple(fitness.shape) != (R, P):
            raise FitnessError(f"fitness must have shape [{R}, {P}] (runs, genomes), got {tuple(fitness.shape)}")
        if fitness.is_complex():  # .to(float64) would drop the imaginary part without a word
            raise FitnessError(f"fitness must be real, got a {fitness.dtype} tensor")
        fitness = fitness.to(device=self.device, dtype=torch.float64)
        bad = ~torch.isfinite(fitness)
        if bool(bad.any()):
            where = torch.nonzero(bad)[:10].tolist()
            raise FitnessError(f"fitness holds NaN or inf for {int(bad.sum())} genome(s), "
                               f"first (run, genome) indices: {where}")
        return fitness

    def _reproduce(self, fitness: Tensor, evolving: list[int]) -> ReproductionInfo:
        """Breed the runs ``evolving``, in chunks of at most ``reproduce_chunk_genomes``
        genomes: runs are independent, so chunking changes no result, and chunks whose gene
        tensors fit in cache keep the cost per genome from rising with R x P."""
        per_chunk = max(1, self.reproduce_chunk_genomes // self.config.pop_size)
        chunks = [evolving[k:k + per_chunk] for k in range(0, len(evolving), per_chunk)]
        infos = [self._reproduce_runs(fitness, chunk) for chunk in chunks]
        if len(infos) == 1:
            return infos[0]
        width = max(i.offspring.shape[1] for i in infos)
        offspring = [torch.nn.functional.pad(i.offspring, (0, width - i.offspring.shape[1])) for i in infos]
        return ReproductionInfo(extinct=torch.cat([i.extinct for i in infos]),
                                stagnant_removed=torch.cat([i.stagnant_removed for i in infos]),
                                split_refused=torch.cat([i.split_refused for i in infos]),
                                offspring=torch.cat(offspring))

    def _reproduce_runs(self, fitness: Tensor, evolving: list[int]) -> ReproductionInfo:
        cfg = self.config
        all_runs = len(evolving) == self.num_runs
        sub = (slice(None),) if all_runs else (torch.tensor(evolving, device=self.device),)
        rng = self.rng if all_runs else self.rng.subset(evolving)
        sp = self.species_state if all_runs else self.species_state.select_runs(sub[0])
        # A subset's parents are read, and its children written, in the whole population
        # (``runs``, ``in_place``): nothing is copied out and back.
        runs = None if all_runs else sub[0]
        # C kernels or tensor operators: decided here, once per generation, for breeding and speciation alike
        fused = breed_kernel.wanted(self.genomes, self.fused_breeding)
        children, _elite, sp, info = reproduce(self.genomes, fitness[sub], self.species[sub], sp, cfg, rng,
                                               self.generation, fused=fused, runs=runs, in_place=not all_runs)
        genes = info.child_genes
        if bool(info.extinct.any()):
            genes = None  # the reset genomes are not the bred ones
            gone = torch.nonzero(info.extinct).flatten().tolist()
            fresh = initial_genomes(cfg, rng.subset(gone), dtype=self.dtype)
            idx = torch.tensor(gone, device=self.device)
            for name, t in children.tensors().items():
                t[idx if all_runs else sub[0][idx]] = getattr(fresh, name)
            sp.alive[idx] = False
            sp.obliterated[idx], sp.run_best[idx], sp.run_stale[idx] = False, -torch.inf, 0  # a fresh run's records
            self._extinct_now.extend(evolving[i] for i in gone)
        species, sp = speciate(children, sp, cfg, rng, self.generation + 1, fused=fused, runs=runs,
                               genes=genes)
        info.child_genes = None  # used; reporters keep the numbers only
        if all_runs:
            self.genomes, self.species, self.species_state = children, species, sp
        else:
            idx = sub[0]
            self.species[idx] = species
            full = self.species_state
            if sp.capacity > full.capacity:
                full = full.grow(sp.capacity)
            elif sp.capacity < full.capacity:
                sp = sp.grow(full.capacity)
            rows = self.device.type == "cpu" and breed_kernel.kernel_available()
            for name, t in full.tensors().items():
                if rows and t.is_contiguous():
                    breed_kernel.put_rows(t, idx, getattr(sp, name))
                else:
                    t[idx] = getattr(sp, name)
            self.species_state = full
        return info

    # --- run ---------------------------------------------------------------------------
    def run(self, fitness_fn: FitnessFn, generations: int, fitness_target: float | None = None,
            solved_fn: Callable[[Genomes, Tensor], Tensor] | None = None) -> NEATResult:
        """Evaluate and breed for up to ``generations`` generations, or until every run has
        solved the task: a genome with fitness >= ``fitness_target`` (default:
        ``config.fitness_threshold``), or, if given, ``solved_fn(genomes, fitness) -> [R, P]`` bool."""
        if isinstance(generations, bool) or not isinstance(generations, int) or generations < 0:
            raise ValueError(f"generations must be a non-negative int, got {generations!r}")
        if fitness_target is not None:
            self.fitness_target = float(fitness_target)
        self.last_status = None
        for _ in range(generations):
            if not bool(self.active_runs.any()):
                break
            self._report("start_generation", self.generation)
            genomes = self.ask()
            fitness = self.evaluate_active(fitness_fn, genomes)
            self.tell(fitness, None if solved_fn is None else self.solved_active(solved_fn, genomes, fitness))
        self._report("end_run", self.last_status)
        return self.result()

    def evaluate_active(self, fitness_fn: FitnessFn, genomes: Genomes) -> Tensor:
        """``fitness_fn`` on the unsolved runs only, ``[R, P]``; solved runs report their champion's fitness.

        Solved runs are frozen, and evaluating them again would cost the most (their genomes
        balance longest) and change nothing.
        """
        active = self.active_runs
        if bool(active.all()):
            return fitness_fn(genomes)
        idx = torch.nonzero(active).flatten()
        R, P = self.num_runs, self.config.pop_size
        part = fitness_fn(genomes.select_runs(idx))
        if not isinstance(part, Tensor) or tuple(part.shape) != (len(idx), P):
            shape = tuple(part.shape) if isinstance(part, Tensor) else type(part).__name__
            raise FitnessError(f"fitness_fn must return [runs, genomes] = [{len(idx)}, {P}] for the "
                               f"{len(idx)} unsolved runs, got {shape}")
        fitness = self.best_fitness.unsqueeze(1).expand(R, P).clone()
        fitness[idx] = part.to(device=self.device, dtype=fitness.dtype)
        return fitness

    def solved_active(self, solved_fn: Callable[[Genomes, Tensor], Tensor], genomes: Genomes,
                      fitness: Tensor) -> Tensor:
        """``solved_fn(genomes, fitness) -> [R, P]`` bool on the unsolved runs only; false for the
        solved runs, which are frozen (a solved_fn that tests champions at length costs the most
        on them, and ``tell`` ignores them)."""
        fitness = self._check_fitness(fitness)
        active = self.active_runs
        R, P = self.num_runs, self.config.pop_size
        if bool(active.all()):
            part, idx = solved_fn(genomes, fitness), None
        else:
            idx = torch.nonzero(active).flatten()
            part = solved_fn(genomes.select_runs(idx), fitness[idx])
        rows = R if idx is None else len(idx)
        if not isinstance(part, Tensor) or part.dtype != torch.bool or tuple(part.shape) != (rows, P):
            got = (tuple(part.shape), part.dtype) if isinstance(part, Tensor) else type(part).__name__
            raise FitnessError(f"solved_fn must return a bool tensor [runs, genomes] = [{rows}, {P}] for the "
                               f"unsolved runs, got {got}")
        if idx is None:
            return part.to(self.device)
        solved = torch.zeros(R, P, dtype=torch.bool, device=self.device)
        solved[idx] = part.to(self.device)
        return solved

    def result(self) -> NEATResult:
        return NEATResult(self.best_fitness.clone(), self.best_genomes.clone(), self.solved_generation.clone(),
                          self.generation, self.solved_position.clone())

    # --- checkpoints -------------------------------------------------------------------
    def _state_problem(self) -> str | None:
        """What is wrong with a restored state's tensors (shapes, dtypes, ranges), or None.

        The C kernels index with these tensors, so a crafted checkpoint must stop here, not there."""
        R, P, N = self.num_runs, self.config.pop_size, self.config.num_nodes
        S = self.species_state.alive.shape[1] if self.species_state.alive.dim() == 2 else -1
        expect = {  # name: (tensor, shape, dtype)
            **{f"genomes.{k}": (getattr(self.genomes, k), (R, P, *tail), dt)
               for k, tail, dt in _genome_fields(self.dtype, N, self.config.compat_mutation_num)},
            **{f"best_genomes.{k}": (getattr(self.best_genomes, k), (R, 1, *tail), dt)
               for k, tail, dt in _genome_fields(self.dtype, N, self.config.compat_mutation_num)},
            "species": (self.species, (R, P), torch.long),
            "species_state.alive": (self.species_state.alive, (R, S), torch.bool),
            "species_state.rep_conn": (self.species_state.rep_conn, (R, S, N, N), torch.bool),
            "species_state.rep_weight": (self.species_state.rep_weight, (R, S, N, N), self.dtype),
            "species_state.rep_sigma": (self.species_state.rep_sigma, (R, S), self.dtype),
            "species_state.best_fitness": (self.species_state.best_fitness, (R, S), torch.float64),
            "species_state.last_improved": (self.species_state.last_improved, (R, S), torch.long),
            "species_state.created": (self.species_state.created, (R, S), torch.long),
            "species_state.ident": (self.species_state.ident, (R, S), torch.long),
            "species_state.next_id": (self.species_state.next_id, (R,), torch.long),
            "best_fitness": (self.best_fitness, (R,), torch.float64),
            "solved_generation": (self.solved_generation, (R,), torch.long),
            "solved_position": (self.solved_position, (R,), torch.long),
        }
        for key, (t, shape, dtype) in expect.items():
            if not isinstance(t, Tensor) or tuple(t.shape) != shape or t.dtype != dtype:
                got = (tuple(t.shape), t.dtype) if isinstance(t, Tensor) else type(t).__name__
                return f"{key} should be {shape} {dtype} for its {R} runs of {P} genomes, got {got}"
        if S < 1:
            return "species_state has no species slots"
        if not 0 <= self.generation < 2**62:  # compared with int64 tensors below
            return f"generation is {self.generation}, not in [0, 2**62)"
        if bool(((self.species < 0) | (self.species >= S)).any()):
            return f"species holds a slot outside [0, {S})"
        if bool(((self.solved_generation < -1) | (self.solved_generation > self.generation)).any()):
            return f"solved_generation lies outside [-1, {self.generation}]"
        if bool(((self.solved_position < -1) | (self.solved_position >= P)).any()):
            return f"solved_position lies outside [-1, {P})"
        if bool(torch.isnan(self.best_fitness).any()):
            return "best_fitness holds NaN"
        return None


    def state_dict(self) -> dict:
        """A snapshot of the whole state (copies: later generations, which write the population
        in place, do not change it), as ``save_checkpoint`` writes and ``from_state_dict`` reads."""
        return {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            "config": self.config.to_dict(),
            "seeds": list(self.rng.seeds),
            "dtype": str(self.dtype).removeprefix("torch."),
            "device": self.device.type,
            "generation": self.generation,
            "fitness_target": self.fitness_target,
            "genomes": {k: _snapshot(v) for k, v in self.genomes.tensors().items()},
            "species": _snapshot(self.species),
            "species_state": {k: _snapshot(v) for k, v in self.species_state.tensors().items()},
            "rng": self.rng.get_state(),
            "best_fitness": _snapshot(self.best_fitness),
            "best_genomes": {k: _snapshot(v) for k, v in self.best_genomes.tensors().items()},
            "solved_generation": _snapshot(self.solved_generation),
            "solved_position": _snapshot(self.solved_position),
        }

    def save_checkpoint(self, path: str | os.PathLike) -> Path:
        """Write the whole state (RNG included) atomically; ``NEAT.restore`` continues bit for bit."""
        return atomic_torch_save(self.state_dict(), path)

    @classmethod
    def restore(cls, path: str | os.PathLike, *, device: str | torch.device | None = None) -> NEAT:
        """Load a checkpoint. Raises ``CheckpointError`` naming the file if it is damaged."""
        data = load_checkpoint_dict(path, map_location="cpu")
        if "neat" in data and "identity" in data:  # written by `snn-neat reproduce/evolve/xor`
            command = data["identity"].get("command", "reproduce") if isinstance(data["identity"], dict) else "reproduce"
            raise CheckpointError(
                f"{os.fspath(path)!r} is a checkpoint of `snn-neat {command}`, which holds a NEAT state and "
                f"the command's own records: continue it with `snn-neat {command} ... --resume`, or take its NEAT "
                "state with NEAT.from_state_dict(load_checkpoint_dict(path)['neat'])")
        return cls.from_state_dict(data, device=device, name=os.fspath(path))

    @classmethod
    def from_state_dict(cls, data: dict, *, device: str | torch.device | None = None,
                        name: str = "<state dict>") -> NEAT:
        """Rebuild a NEAT from ``state_dict()``; ``name`` labels errors (the file it came from)."""
        try:
            config = NEATConfig(**data["config"])
            dtype = {"float32": torch.float32, "float64": torch.float64}.get(data["dtype"])
            if dtype is None:
                raise CheckpointError(f"checkpoint {name!r} is malformed: dtype {data['dtype']!r} is not "
                                      "float32 or float64")
            saved = torch.device(data["device"])
            target = torch.device(device) if device is not None else saved
            if target.type != saved.type:
                raise CheckpointError(f"checkpoint {name!r} was written on {saved.type}; its random streams only "
                                      f"continue bit for bit there, so restore it on {saved.type}, not {target.type}")
            self = cls.__new__(cls)
            self.config = config
            self.dtype = dtype
            self.rng = RunRNG(data["seeds"], target)
            self.generation = int(data["generation"])
            self.fitness_target = float(data["fitness_target"])
            self.reporters = []
            self.last_status = None
            self._extinct_now = []
            # Copies: the population is written in place, and must not write into ``data``.
            self.genomes = Genomes(**{k: v.to(target, copy=True, memory_format=torch.contiguous_format)
                                      for k, v in data["genomes"].items()})
            self.species = data["species"].to(target, copy=True)
            self.species_state = SpeciesState(**{k: v.to(target, copy=True)
                                                 for k, v in data["species_state"].items()})
            self.best_fitness = data["best_fitness"].to(target, copy=True)
            self.best_genomes = Genomes(**{k: v.to(target, copy=True) for k, v in data["best_genomes"].items()})
            self.solved_generation = data["solved_generation"].to(target, copy=True)
            position = data.get("solved_position")  # absent in checkpoints written before it was kept
            self.solved_position = (torch.full_like(self.solved_generation, -1) if position is None
                                    else position.to(target, copy=True))
            self.rng.set_state(data["rng"])
        except CheckpointError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError, RuntimeError, OverflowError, IndexError) as exc:
            raise CheckpointError(f"checkpoint {name!r} is malformed ({type(exc).__name__}: {exc})") from exc
        problem = self._state_problem()
        if problem:
            raise CheckpointError(f"checkpoint {name!r} is malformed: {problem}")
        try:  # the distances and the kernels rely on them (no gene: weight 0), so a damaged population stops here
            check_invariants(self.genomes, config)
        except InvariantError as exc:
            raise CheckpointError(f"checkpoint {name!r} is malformed: its population breaks an invariant ({exc})") from exc
        return self


def _seed_list(seeds: Iterable[int]) -> list[int]:
    """``seeds`` as Python ints; a float or bool is refused rather than truncated (1.5 is not seed 1)."""
    out = []
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, numbers.Integral):
            raise ValueError(f"seeds must be non-negative integers below 2**63, got {s!r}")
        out.append(int(s))
    return out


def _snapshot(t: Tensor) -> Tensor:
    """A CPU copy of ``t`` that shares no memory with it."""
    return t.detach().to("cpu", copy=True)
