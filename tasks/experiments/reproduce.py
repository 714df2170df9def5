"""Reproduce the paper's Tables I and II: many seeded runs per controller, resumable.

All runs of one controller evolve in one batch (run axis R). After every
``checkpoint_every`` generations the whole state (NEAT state with its RNG streams, and the
best-fitness history for Fig. 8) is written atomically to ``OUT/<controller>.ckpt``, so a
reproduction killed at any point resumes with ``resume=True`` and ends with the same table
as an uninterrupted one. Solved runs are frozen (not evaluated again).

A run's score is its solving generation (1-based, as the paper counts); a run that does
not solve within ``generations`` counts as ``generations + 1`` (the paper's 101).
"""

from __future__ import annotations

import functools
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch import Tensor

from evolution.checkpoint import CheckpointError, atomic_torch_save, load_checkpoint_dict
from evolution.config import NEATConfig
from evolution.neat import NEAT
from evolution.population import Genomes

__all__ = ["PAPER", "TASKS", "ControllerRuns", "ReproduceError", "run_controller", "summarize"]

# [Qiu19] Tables I and II (failures counted as 101 generations in median and mean).
PAPER = {
    "table1": {"sigmoid": {"best": 3, "worst": 55, "median": 17.5, "mean": 21.68, "failures": 1, "runs": 60},
               "snn": {"best": 1, "worst": 92, "median": 9.5, "mean": 16.55, "failures": 1, "runs": 60}},
    "table2": {"sigmoid": {"best": 8, "worst": 96, "median": 44, "mean": 50.35, "failures": 7, "runs": 60},
               "snn": {"best": 5, "worst": 65, "median": 21.5, "mean": 24.70, "failures": 0, "runs": 60}},
}
LABELS = {"snn": "NEAT-SNN", "sigmoid": "NEAT original (sigmoid)"}


class ReproduceError(ValueError):
    """A reproduction cannot start or resume as asked (the message names the option)."""


@dataclass(frozen=True)
class Task:
    """One of the paper's tasks: how to configure and score each controller."""

    name: str
    description: str
    config: Callable[..., NEATConfig]  # (controller, self_loops=...) -> NEATConfig
    fitness: Callable[..., Callable[[Genomes], Tensor]]  # (controller, config) -> fitness_fn
    max_steps: int
    tau_s: float
    # (controller, config) -> solved_fn(genomes, fitness) -> [R, P] bool, or None where the
    # config's fitness threshold decides
    solved: Callable[..., Callable[[Genomes, Tensor], Tensor] | None] | None = None


def _tasks() -> dict[str, Task]:
    from tasks.experiments import cartpole as cp
    from tasks.experiments import double_pole as dp

    def study(variant: str, description: str) -> Task:
        task = dp.study_task(variant)
        return Task(variant, description, functools.partial(dp.study_config, variant),
                    functools.partial(dp.study_fitness, variant), task.max_steps, task.plant.tau_s,
                    functools.partial(dp.study_solved, variant))

    return {
        "dpv": study("dpv", "double-pole balancing with velocities (NEAT 2002): six inputs, +-10 N, population 150, "
                     "solved when a genome balances 100,000 steps"),
        "dpnv": study("dpnv", "double-pole balancing without velocities (NEAT 2002): x and both angles, Gruau's "
                      "damping fitness over 1000 steps, population 1000, solved when a champion balances 100,000 "
                      "steps and 200 of the 625 generalisation starts"),
        "table1": Task("table1", "Markov cart-pole (Table I): x, x_dot, theta, theta_dot as Bernoulli-coded input "
                       "spikes, bang-bang +-10 N, tau 20 ms, success at 100,000 steps",
                       cp.markov_config, cp.markov_fitness, cp.MARKOV["max_steps"], cp.MARKOV["tau_s"]),
        "table2": Task("table2", "non-Markov cart-pole (Table II): x and theta only, continuous force, tau 10 ms, "
                       "start at 3 degrees, success at 5000 steps",
                       cp.controller_config, cp.nonmarkov_fitness, cp.NONMARKOV["max_steps"], cp.NONMARKOV["tau_s"]),
    }


TASKS = ("table1", "table2", "dpv", "dpnv")
IDENTITY_DEFAULTS = {"coding": "study", "champion_test": "champion"}  # checkpoints from before the key: this value
CHAMPION_TESTS = ("champion", "species")
# Fig. 8 draws solved runs' final best up to the budget, or this many generations where the
# budget is larger (evolution itself may go on longer; its generations are all drawn).
FIG8_MAX_PAD = 10_000


@dataclass
class ControllerRuns:
    """Everything a table row, Fig. 8 and the champion plots need, for one controller."""

    controller: str
    seeds: list[int]
    generations: int
    solved_generation: list[int]  # 1-based; -1 = not solved within the budget
    best_fitness: list[float]  # champion's fitness (control steps) per run
    history: Tensor  # [generations, R]: best fitness so far after each generation
    champions: Genomes  # [R, 1]
    config: NEATConfig
    wall_s: float
    extra: dict = field(default_factory=dict)

    def champion_sizes(self) -> tuple[list[int], list[int]]:
        """Each run's champion: hidden nodes and enabled connections."""
        c = self.config
        hidden = self.champions.node[:, 0].sum(-1) - c.num_inputs - c.num_bias - c.num_outputs
        return hidden.tolist(), self.champions.enabled[:, 0].sum((-1, -2)).tolist()

    def counted(self) -> list[int]:
        """Solving generation per run, failures as ``generations + 1``."""
        return [g if g > 0 else self.generations + 1 for g in self.solved_generation]

    def row(self) -> dict:
        counted = self.counted()
        failures = sum(g <= 0 for g in self.solved_generation)
        return {"controller": self.controller, "best": min(counted), "worst": max(counted),
                "median": statistics.median(counted), "mean": statistics.mean(counted),
                "failures": failures, "runs": len(counted), "failure_rate": f"{failures}/{len(counted)}",
                "wall_s": self.wall_s, "ga": self.extra.get("ga", ""),
                **({"coding": self.extra["coding"]} if self.extra.get("coding", "study") != "study" else {})}


def _progress(total: int, initial: int, desc: str, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="gen", disable=not enabled, file=sys.stderr)


def study_config(task_name: str, controller: str, *, self_loops: bool = False, ga: str = "tuned",
                 coding: str = "study") -> NEATConfig:
    """The NEAT config ``run_controller`` evolves ``controller`` with on ``task_name`` (the CLI's
    memory check reads it too). ``coding``: the double-pole studies' input coding
    (``tasks.experiments.double_pole.CODINGS``); the paper's tables have only their own."""
    from tasks.experiments.cartpole import ga_choice

    tasks = _tasks()
    if task_name not in tasks:
        raise ReproduceError(f"table must be one of {TASKS}, got {task_name!r}")
    try:
        preset, ga_extra = ga_choice(task_name, controller, ga)
    except ValueError as exc:
        raise ReproduceError(str(exc)) from None
    return tasks[task_name].config(controller, self_loops=self_loops, ga=preset, **_coding_kwargs(task_name, coding),
                                   **ga_extra)


def _coding_kwargs(task_name: str, coding: str) -> dict:
    """``{"coding": coding}`` for a coding other than the study's own (none for the default), checked:
    ``"signed"`` is NEAT C++ 1.2.1's coding on the double pole, the paper's bounds signed on its
    tables (``tasks.experiments.cartpole.paper_spec``), a sensitivity study there."""
    from tasks.experiments.double_pole import CODINGS

    if coding not in CODINGS:
        raise ReproduceError(f"coding must be one of {CODINGS}, got {coding!r}")
    return {} if coding == "study" else {"coding": coding}


def run_controller(task_name: str, controller: str, seeds: list[int], generations: int, out: str | os.PathLike,
                   *, resume: bool = False, self_loops: bool = False, ga: str = "tuned", checkpoint_every: int = 1,
                   device: str | torch.device = "cpu", progress: bool = True,
                   stop_after: int | None = None, coding: str = "study",
                   champion_test: str = "champion") -> ControllerRuns:
    """Evolve ``controller`` on ``task_name`` for each seed (one batch), checkpointing to ``out``.

    ``resume`` continues from ``OUT/<controller>.ckpt`` (which must have been written with
    the same task, seeds, budget and start genome); without it an existing checkpoint is an
    error, so a finished reproduction is never overwritten by accident. ``ga``: a GA preset of
    ``tasks.experiments.cartpole.GA_PRESETS``, or ``"tuned"`` (default), the controller's own
    pick for the table (``TUNED_GA``). ``coding``: the double-pole studies' input coding
    (``"study"``, or ``"signed"``: NEAT 1.2.1's). ``champion_test``: DPNV's test of a
    generation, ``"champion"`` (each run's overall champion, every generation) or ``"species"``
    (NEAT C++ 1.2.1's: the champion of the best species not tested since it improved; its record
    is kept in the checkpoint). ``stop_after`` (generations in this call) exists for tests of
    interruption.
    """
    from tasks.experiments.cartpole import describe_ga, ga_choice

    tasks = _tasks()
    if task_name not in tasks:
        raise ReproduceError(f"table must be one of {TASKS}, got {task_name!r}")
    task = tasks[task_name]
    try:
        preset, ga_extra = ga_choice(task_name, controller, ga)
    except ValueError as exc:
        raise ReproduceError(str(exc)) from None
    ga_text = describe_ga(preset, ga_extra)
    if checkpoint_every < 1:
        raise ReproduceError(f"checkpoint_every must be >= 1, got {checkpoint_every}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{controller}.ckpt"
    coding_kwargs = _coding_kwargs(task_name, coding)
    if champion_test not in CHAMPION_TESTS or (champion_test != "champion" and task_name != "dpnv"):
        raise ReproduceError(f"champion_test must be one of {CHAMPION_TESTS} ('species' only for dpnv), got "
                             f"{champion_test!r} for {task_name}")
    identity = {"task": task_name, "controller": controller, "seeds": list(seeds), "generations": generations,
                "self_loops": self_loops, "ga": ga_text, "coding": coding, "champion_test": champion_test}
    if path.exists():
        if not resume:
            raise ReproduceError(f"{path} exists: pass --resume to continue it, or choose another --out")
        data = load_checkpoint_dict(path, map_location="cpu")
        saved = data.get("identity")
        saved = saved if isinstance(saved, dict) else {}
        for key, value in identity.items():
            if saved.get(key, IDENTITY_DEFAULTS.get(key)) != value:  # keys added since: their default
                raise ReproduceError(f"cannot resume {path}: it was written with {key}={saved.get(key)!r}, "
                                     f"this call asks for {key}={value!r}")
        neat, history, wall = _resumed(path, data, device)
        config = neat.config
        solved_state = data.get("solved_state")
    else:
        config = study_config(task_name, controller, self_loops=self_loops, ga=ga, coding=coding)
        neat = NEAT(config, seeds=seeds, device=device)
        history, wall, solved_state = [], 0.0, None

    fitness_fn = task.fitness(controller, config, **coding_kwargs)
    solved_fn = None
    if task.solved is not None:
        species = {"neat": neat} if champion_test == "species" else {}
        solved_fn = task.solved(controller, config, **coding_kwargs, **species)
    if solved_state is not None and hasattr(solved_fn, "load_state_dict"):
        try:
            solved_fn.load_state_dict(solved_state)
        except ValueError as exc:
            raise CheckpointError(f"checkpoint {str(path)!r} is malformed: {exc}") from None

    def save() -> None:
        stacked = torch.stack(history) if history else torch.zeros(0, len(seeds), dtype=torch.float64)
        state = neat.state_dict()
        extra = {"solved_state": solved_fn.state_dict()} if hasattr(solved_fn, "state_dict") else {}
        atomic_torch_save({"format": state["format"], "version": state["version"], "identity": identity, "neat": state,
                           "history": stacked, "wall_s": wall, **extra}, path)

    bar = _progress(generations, neat.generation, f"{task_name} {controller}", progress)
    done_here = 0
    try:
        while neat.generation < generations and bool(neat.active_runs.any()):
            if stop_after is not None and done_here >= stop_after:
                break
            start = time.perf_counter()
            genomes = neat.ask()
            fitness = neat.evaluate_active(fitness_fn, genomes)
            neat.tell(fitness, None if solved_fn is None else neat.solved_active(solved_fn, genomes, fitness))
            history.append(neat.best_fitness.detach().cpu().clone())
            wall += time.perf_counter() - start
            done_here += 1
            bar.update(1)
            bar.set_postfix(solved=f"{int((neat.solved_generation > 0).sum())}/{neat.num_runs}",
                            best=f"{neat.best_fitness.max().item():.4g}")
            finished = neat.generation >= generations or not bool(neat.active_runs.any())
            if neat.generation % checkpoint_every == 0 or finished:
                save()
    finally:
        bar.close()
    if stop_after is None and history and (neat.generation >= generations or not bool(neat.active_runs.any())):
        save()
    hist = torch.stack(history) if history else torch.zeros(0, len(seeds), dtype=torch.float64)
    # Runs that solved early keep their final best for the rest of the budget (Fig. 8), drawn
    # up to FIG8_MAX_PAD generations: a budget of 10**12 cannot be padded (nor plotted).
    pad_to = min(generations, max(hist.shape[0], FIG8_MAX_PAD))
    if 0 < hist.shape[0] < pad_to:
        hist = torch.cat([hist, hist[-1:].expand(pad_to - hist.shape[0], -1)])
    return ControllerRuns(controller=controller, seeds=list(seeds), generations=generations,
                          solved_generation=neat.solved_generation.cpu().tolist(),
                          best_fitness=neat.best_fitness.cpu().tolist(), history=hist,
                          champions=neat.best_genomes.to("cpu"), config=config, wall_s=wall,
                          extra={"complete": neat.generation >= generations or not bool(neat.active_runs.any()),
                                 "ga": ga_text, "coding": coding, "champion_test": champion_test,
                                 "solved_position": neat.solved_position.cpu().tolist()})


def _resumed(path: Path, data: dict, device: str | torch.device) -> tuple[NEAT, list[Tensor], float]:
    """The NEAT state, Fig. 8 history (one ``[R]`` float64 row per generation) and wall time
    of a checkpoint, each checked: a crafted or damaged file stops here, naming itself."""
    from evolution.checkpoint import CheckpointError

    if not isinstance(data.get("neat"), dict):
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: it holds no NEAT state")
    neat = NEAT.from_state_dict(data["neat"], device=device, name=str(path))
    history, wall = data.get("history"), data.get("wall_s")
    shape = (neat.generation, neat.num_runs)
    if not isinstance(history, Tensor) or history.dtype != torch.float64 or tuple(history.shape) != shape:
        got = (tuple(history.shape), history.dtype) if isinstance(history, Tensor) else type(history).__name__
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: its history should be {shape} float64 "
                              f"(generations, runs), got {got}")
    if isinstance(wall, bool) or not isinstance(wall, (int, float)) or not 0 <= wall < float("inf"):
        raise CheckpointError(f"checkpoint {str(path)!r} is malformed: wall_s is {wall!r:.40}")
    return neat, list(history.unbind(0)), float(wall)


def mann_whitney(a: list[int], b: list[int]) -> dict:
    """Two-sided Mann-Whitney U test (scipy) of generations-to-solve, failures as 101."""
    from scipy.stats import mannwhitneyu

    if len(set(a) | set(b)) == 1:
        return {"U": float("nan"), "p_value": 1.0, "note": "all values equal"}
    res = mannwhitneyu(a, b, alternative="two-sided")
    return {"U": float(res.statistic), "p_value": float(res.pvalue)}


def summarize(results: dict[str, ControllerRuns], table: str) -> dict:
    """Rows, the U-test and the paper's rows, as one JSON-able dict."""
    rows = {c: r.row() for c, r in results.items()}
    out = {"table": table, "rows": rows, "paper": PAPER.get(table, {})}
    if "snn" in results and "sigmoid" in results:
        out["mann_whitney_u"] = mann_whitney(results["snn"].counted(), results["sigmoid"].counted())
    return out


def format_markdown(summary: dict, seeds: list[int], command: str) -> str:
    """The table as the paper prints it, ours beside the paper's."""
    lines = [f"# {summary['table'].replace('table', 'Table ')} reproduced", "",
             f"Command: `{command}`", f"Seeds: {seeds[0]}..{seeds[-1]} ({len(seeds)} runs per controller)", "",
             "| Controller | Source | Best | Worst | Median | Mean | Failure rate | Wall time (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for c, row in summary["rows"].items():
        lines.append(f"| {LABELS.get(c, c)} | this code | {row['best']} | {row['worst']} | {row['median']:g} | "
                     f"{row['mean']:.2f} | {row['failure_rate']} | {row['wall_s']:.0f} |")
        paper = summary["paper"].get(c)
        if paper:
            lines.append(f"| {LABELS.get(c, c)} | paper | {paper['best']} | {paper['worst']} | {paper['median']:g} | "
                         f"{paper['mean']:.2f} | {paper['failures']}/{paper['runs']} | |")
    lines += ["", "Median and mean count a failed run (no solution within the budget) as budget + 1 generations."]
    ga = [f"{LABELS.get(c, c)}: {row['ga']}" for c, row in summary["rows"].items() if row.get("ga")]
    if ga:
        lines.append("GA settings (tasks/experiments/cartpole.py, GA_PRESETS and TUNED_GA): " + "; ".join(ga) + ".")
    if any(row.get("coding") == "signed" for row in summary["rows"].values()):
        lines.append("Input coding: signed (`--coding signed`, a sensitivity study, not the paper's): each observation "
                     "in [-1, 1] over the paper's bounds, centred; the Bernoulli encoder's as push-pull pairs of input "
                     "neurons (tasks/experiments/cartpole.py, paper_spec).")
    if "mann_whitney_u" in summary:
        mw = summary["mann_whitney_u"]
        p = mw["p_value"]
        lines.append(f"Mann-Whitney U (two-sided, NEAT-SNN vs sigmoid NEAT): U = {mw['U']:g}, p = {p:.3g}"
                     + (" (significant at 0.01)" if p < 0.01 else " (not significant at 0.01)"))
    return "\n".join(lines) + "\n"




# --- the report ----------------------------------------------------------------------
# Table I episodes last 100,000 steps; its plot shows the first 20 s (the torch reference path
# records it, about 5 s of compute for the spiking controller).
MARKOV_RECORD_STEPS = 1000


def _record_episode(r: ControllerRuns, task: str, run: int) -> tuple[dict, float]:
    """One champion's episode from the task's start state, recorded step by step; and tau (s)."""
    from evolution.phenotype import make_controller
    from evolution.rollout import rollout
    from tasks.experiments import cartpole as cp

    one = r.champions.select_runs([run])
    steps = None if task == "table2" else MARKOV_RECORD_STEPS
    plant_task = cp.paper_task(task, max_steps=steps)
    spec = cp.paper_spec(task, r.controller, r.extra.get("coding", "study"))  # the coding it evolved with
    controller = make_controller(one, r.config, plant_task, spec, kind=r.controller)
    trace = rollout(plant_task, controller, record=True).trace
    state = trace["state"][:, 0]
    out = {"x": state[:, 0], "theta": state[:, 2], "force": trace["action"][:, 0, 0],
           "activity": trace["activity"][:, 0],
           "nodes": controller.nodes if r.controller == "snn" else None}
    return out, plant_task.control_period_s


def _example_run(r: ControllerRuns) -> int:
    """The first solved run (the paper plots a solved controller), else the fittest."""
    solved = [i for i, g in enumerate(r.solved_generation) if g > 0]
    return solved[0] if solved else max(range(len(r.best_fitness)), key=r.best_fitness.__getitem__)


def _generalization(r: ControllerRuns) -> list[float]:
    from tasks.experiments.cartpole import paper_spec
    from tasks.generalization import success_rate

    spec = paper_spec("table2", r.controller, r.extra.get("coding", "study"))  # the coding it evolved with
    rate = success_rate(r.champions, r.config, controller=r.controller, spec=spec)  # [R, 1]
    return rate[:, 0].tolist()


def _save_png(fig, path: Path) -> Path:
    """``fig`` as PNG (150 dpi), written atomically with the umask's mode."""
    import io

    from evolution.checkpoint import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=150)
    return atomic_write_bytes(path, buf.getvalue())


def write_report(results: dict[str, ControllerRuns], table: str, out: str | os.PathLike, *, command: str,
                 generalization: bool = True) -> list[Path]:
    """Write the table (Markdown, CSV), per-run CSV, summary JSON, Fig. 8, an example
    trajectory and topology per controller, and every champion genome. Returns the paths.

    ``summary.json`` and then ``TABLE.md`` are written last, and removed first: a report
    interrupted part way has no ``TABLE.md``, so one that has it is complete."""
    import csv
    import io
    import json

    from evolution.checkpoint import atomic_write_bytes
    from evolution.genome_io import save_genome
    from tasks.experiments.double_pole import VARIANTS
    from tasks.plots import plot_best_fitness_mean_std, plot_episode, plot_topology, plot_trajectory

    if table in VARIANTS:
        from tasks.experiments.double_pole_report import write_study_report

        return write_study_report(results, table, out, command=command, generalization=generalization)
    out = Path(out)
    for last in (out / f"{table}.md", out / "summary.json"):
        last.unlink(missing_ok=True)
    written: list[Path] = []
    summary = summarize(results, table)
    seeds = next(iter(results.values())).seeds
    if generalization and table == "table2":
        for c, r in results.items():
            rates = _generalization(r)
            r.extra["generalization"] = rates
            summary["rows"][c]["generalization_mean"] = statistics.mean(rates)
            summary["rows"][c]["generalization_median"] = statistics.median(rates)
            solved = [x for x, g in zip(rates, r.solved_generation, strict=True) if g > 0]
            summary["rows"][c]["generalization_solved_mean"] = statistics.mean(solved) if solved else float("nan")
    summary["command"] = command
    summary["seeds"] = seeds
    md = format_markdown(summary, seeds, command)
    if "generalization_mean" in next(iter(summary["rows"].values())):
        md += ("\nGeneralisation (beyond the paper): fraction of the 625 start states of Gruau et al. (1996), "
               "scaled to this plant, that each run's champion balances for 1000 steps.\n\n"
               "| Controller | mean over runs | median | mean over solved runs |\n|---|---|---|---|\n")
        for c, row in summary["rows"].items():
            md += (f"| {LABELS.get(c, c)} | {row['generalization_mean']:.3f} | {row['generalization_median']:.3f} | "
                   f"{row['generalization_solved_mean']:.3f} |\n")

    buf = io.StringIO()
    fields = ["controller", "source", "best", "worst", "median", "mean", "failures", "runs", "wall_s"]
    w = csv.DictWriter(buf, fieldnames=fields, extrasaction="ignore")
    w.writeheader()
    for c, row in summary["rows"].items():
        w.writerow({**row, "source": "this code"})
        if c in summary["paper"]:
            w.writerow({"controller": c, "source": "paper", **summary["paper"][c]})
    written.append(atomic_write_bytes(out / f"{table}.csv", buf.getvalue().encode()))

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["controller", "run", "seed", "solved_generation", "counted_generations", "best_fitness",
                "hidden_nodes", "enabled_connections", "generalization"])
    for c, r in results.items():
        hidden, conns = r.champion_sizes()
        gen = r.extra.get("generalization", [""] * len(r.seeds))
        for i, seed in enumerate(r.seeds):
            w.writerow([c, i, seed, r.solved_generation[i], r.counted()[i], r.best_fitness[i], int(hidden[i]),
                        int(conns[i]), gen[i]])
    written.append(atomic_write_bytes(out / "runs.csv", buf.getvalue().encode()))

    target = float(next(iter(results.values())).config.fitness_threshold)
    fig = plot_best_fitness_mean_std({LABELS.get(c, c): r.history.T for c, r in results.items()}, max_fitness=target,
                                     title=f"Best fitness per generation over {len(seeds)} runs (Fig. 8)")
    written.append(_save_png(fig, out / "fig8_best_fitness.png"))
    for c, r in results.items():
        run = _example_run(r)
        label = f"{LABELS.get(c, c)}, seed {r.seeds[run]}" + (
            f", solved at generation {r.solved_generation[run]}" if r.solved_generation[run] > 0 else ", not solved")
        tr, tau = _record_episode(r, table, run)
        if table == "table1":
            label += f" (first {len(tr['x']) * tau:g} s)"
        inputs = {0: "x", 1: "θ"} if r.config.num_inputs == 2 else {0: "x", 1: "ẋ", 2: "θ", 3: "θ̇"}
        if c == "snn":
            node_names = {**inputs, r.config.first_output: "out"}
            names = [f"{node_names.get(int(n), 'hidden')} ({int(n)})" for n in tr["nodes"]]
            fig = plot_episode(tr["activity"], tr["x"], tr["theta"], tr["force"], tau_s=tau, names=names, title=label)
        else:
            fig = plot_trajectory(tr["x"], tr["theta"], tr["force"], tau_s=tau, title=label)
        written.append(_save_png(fig, out / f"trajectory_{c}.png"))
        names = {**inputs, r.config.first_output: "F"}
        written.append(_save_png(plot_topology(r.champions, r.config, run, 0, labels=names,
                                               title=f"Champion topology: {label}"), out / f"topology_{c}.png"))
        for i, seed in enumerate(r.seeds):
            written.append(save_genome(out / "champions" / f"{c}_seed{seed}.json", r.champions.select_runs([i]),
                                       r.config, fitness=r.best_fitness[i]))
    written.append(atomic_write_bytes(out / "summary.json", json.dumps(summary, indent=2, default=float).encode()))
    written.append(atomic_write_bytes(out / f"{table}.md", md.encode()))  # last: the report is complete
    return written
