"""NEAT-SNN and sigmoid NEAT on gymnasium's five classic-control environments (their batched
torch ports, ``tasks.gym_adapter.GymTask``), on a fixed seed set, against gymnasium's reward
thresholds.

    python -m experiments.classic_control                                  # everything, seeds 0-4
    python -m experiments.classic_control --envs CartPole-v1 Acrobot-v1 --controllers sigmoid \\
        --seeds 0 1 --generations 10 --out /tmp/cc

Each run (one environment, one controller, one seed) evolves ``--pop-size`` genomes, each scored
on ``episodes`` fresh seeded episodes per generation (``TaskFitness(..., fresh_starts=True)``:
new start states every generation, so a run cannot learn a fixed few). Training fitness on a
few episodes is noisy, so reaching the threshold is checked twice:

* ``train_generation``: the first generation whose best training fitness reached the threshold
  (-1: never); ``evaluations`` and ``wall_s`` count the training genome-episodes and seconds up
  to it (or of the whole run where it never did).
* the run stops only when a genome that reached the threshold in training also reaches it on
  ``--validation-episodes`` held-out episodes (the same held-out starts every generation; the
  best five such genomes are checked): ``confirmed_generation``.

The champion is the confirmed genome, or, where none was confirmed within the budget, the best on
the held-out episodes among the final generation's 20 fittest and the run's best-ever genome (a
champion picked on noisy training fitness alone tests worse). It is then tested on
``--test-episodes`` fresh seeded episodes (a seed of its own): ``test_mean`` and ``test_worst``;
``test_reaches`` says whether the test mean meets the threshold. This logic is
``tasks.studies.threshold_runs``, which ``snn-neat evolve ENV`` runs too (there with the
library's defaults, not this study's settings).

Writes ``OUT/results.json`` (settings, every run with its best training fitness per generation,
a summary per environment and controller), ``OUT/runs.csv`` (one row per run), ``OUT/summary.md``
(the table), ``OUT/training.png`` (best training fitness per generation) and ``OUT/test_returns.png``
(each champion's test mean and worst per controller against the threshold), each atomically.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import io
import json
import math
import shlex
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from evolution import (
    NEAT,
    BaseReporter,
    SigmoidSpec,
    SpikingSpec,
    TaskFitness,
    task_config,
)
from evolution.checkpoint import atomic_write_bytes
from evolution.defaults import RANDOM_START_EPISODES, TASK_GA, default_spec
from evolution.reporters import GenerationStatus
from tasks.studies.env_task import gym_task
from tasks.studies.threshold_runs import (
    CONFIRM_CANDIDATES,
    FINAL_CANDIDATES,
    TEST_SEED,
    VALIDATION_EPISODES,
    VALIDATION_SEED,
    evolve_to_threshold,
)

__all__ = ["ENVIRONMENTS", "CONTROLLERS", "EnvSetting", "controller_spec", "make_task", "evolve_run", "main"]


@dataclass(frozen=True)
class EnvSetting:
    """One environment's study settings: gymnasium's reward ``threshold`` and the generation budget."""

    threshold: float
    generations: int


# Generation budgets (a run stops once its champion is confirmed). Every other setting is the
# library's default for the task (evolution.defaults: task_config, TaskFitness, default_spec), as
# `snn-neat evolve ENV` runs it: 16 fresh episodes per genome per generation, signed inputs, ...
ENVIRONMENTS: dict[str, EnvSetting] = {
    "CartPole-v1": EnvSetting(475.0, 50),
    "Acrobot-v1": EnvSetting(-100.0, 50),
    "MountainCar-v0": EnvSetting(-110.0, 100),
    "MountainCarContinuous-v0": EnvSetting(90.0, 50),
    "Pendulum-v1": EnvSetting(-200.0, 100),
}
CONTROLLERS = ("snn", "sigmoid")
SEEDS = (0, 1, 2, 3, 4)


def controller_spec(env_id: str, controller: str) -> SpikingSpec | SigmoidSpec:
    """The library's default spec of ``controller`` for ``env_id``'s task (``default_spec``)."""
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    return default_spec(make_task(env_id), controller)


def make_task(env_id: str):
    """The torch port of ``env_id`` as ``snn-neat evolve ENV`` makes it (``tasks.studies.env_task``)."""
    return gym_task(env_id)[0]


class _Progress(BaseReporter):
    """Moves the study's progress bar one generation on, showing the best training fitness."""

    def __init__(self, bar) -> None:
        self.bar = bar

    def end_generation(self, status: GenerationStatus) -> None:
        self.bar.update(1)
        self.bar.set_postfix(best=f"{float(status.fitness.max()):.1f}", refresh=False)


def evolve_run(env_id: str, controller: str, seed: int, *, generations: int, episodes: int, pop_size: int,
               validation_episodes: int, test_episodes: int, progress=None) -> dict:
    """One run (``tasks.studies.threshold_runs``: held-out checks at the threshold, the champion's
    pick and test); returns its record (see the module docstring)."""
    setting = ENVIRONMENTS[env_id]
    threshold = setting.threshold
    task = make_task(env_id)
    config = task_config(task, controller, pop_size=pop_size, fitness_threshold=threshold)
    if episodes is None:  # the library's default episodes
        fitness = TaskFitness(task, config, controller, seed=seed)
        episodes = fitness.episodes
    else:
        fitness = TaskFitness(task, config, controller, episodes=episodes, seed=seed, fresh_starts=True)
    spec = fitness.spec
    neat = NEAT(config, seeds=[seed])
    runs = evolve_to_threshold(neat, fitness, task, spec, threshold, generations, episodes_per_genome=episodes,
                               validation_episodes=validation_episodes, test_episodes=test_episodes,
                               reporters=[] if progress is None else [_Progress(progress)])
    r = runs.records[0]
    if progress is not None and r.generations < generations:
        progress.update(generations - r.generations)
    reached = r.train_generation > 0
    return {"env": env_id, "controller": controller, "seed": seed, "threshold": threshold,
            "train_generation": r.train_generation, "evaluations": r.train_episodes if reached else r.episodes,
            "wall_s": round(r.train_wall_s if reached else r.wall_s, 2),
            "confirmed_generation": r.confirmed_generation, "generations_run": r.generations,
            "total_evaluations": r.episodes, "validation_evaluations": r.validation_episodes,
            "total_wall_s": round(r.wall_s, 2), "best_training_fitness": max(r.history),
            "champion_validation_mean": r.champion_validation,
            "test_mean": r.test_mean, "test_worst": r.test_worst, "test_reaches": r.test_mean >= threshold,
            "champion_hidden": r.champion_hidden, "champion_genes": r.champion_genes, "history": r.history}


def summarize(runs: list[dict]) -> list[dict]:
    """One row per (environment, controller), in the order the runs came."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in runs:
        groups.setdefault((r["env"], r["controller"]), []).append(r)
    rows = []
    for (env, controller), rs in groups.items():
        reached = [r for r in rs if r["train_generation"] > 0]
        rows.append({
            "env": env, "controller": controller, "threshold": rs[0]["threshold"], "runs": len(rs),
            "train_reached": len(reached), "confirmed": sum(r["confirmed_generation"] > 0 for r in rs),
            "test_reached": sum(r["test_reaches"] for r in rs),
            "median_train_generation": statistics.median(r["train_generation"] for r in reached) if reached else None,
            "median_evaluations": statistics.median(r["evaluations"] for r in reached) if reached else None,
            "median_wall_s": statistics.median(r["wall_s"] for r in reached) if reached else None,
            "median_test_mean": statistics.median(r["test_mean"] for r in rs),
            "best_test_mean": max(r["test_mean"] for r in rs),
            "worst_test_return": min(r["test_worst"] for r in rs),
            "total_wall_s": round(sum(r["total_wall_s"] for r in rs), 1),
        })
    return rows


CSV_FIELDS = ("env", "controller", "seed", "threshold", "train_generation", "evaluations", "wall_s",
              "confirmed_generation", "generations_run", "total_evaluations", "validation_evaluations",
              "total_wall_s", "best_training_fitness", "champion_validation_mean", "test_mean", "test_worst",
              "test_reaches", "champion_hidden", "champion_genes")
LABELS = {"snn": "NEAT-SNN", "sigmoid": "sigmoid NEAT"}
COLORS = {"snn": "tab:red", "sigmoid": "tab:blue"}


def _fmt(value, digits: int = 1) -> str:
    if value is None:
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def summary_markdown(summary: list[dict], test_episodes: int) -> str:
    lines = [f"| environment | threshold | controller | runs reaching it in training | confirmed on held-out | "
             f"champion test mean reaching it ({test_episodes} episodes) | median generation (training) | "
             f"median evaluations | median wall s | median test mean | best test mean | worst test return |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        n = s["runs"]
        lines.append(f"| {s['env']} | {s['threshold']:g} | {LABELS[s['controller']]} | {s['train_reached']}/{n} | "
                     f"{s['confirmed']}/{n} | {s['test_reached']}/{n} | {_fmt(s['median_train_generation'])} | "
                     f"{_fmt(s['median_evaluations'], 0)} | {_fmt(s['median_wall_s'])} | "
                     f"{s['median_test_mean']:.1f} | {s['best_test_mean']:.1f} | {s['worst_test_return']:.1f} |")
    return "\n".join(lines) + "\n"


def _save_png(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return atomic_write_bytes(path, buf.getvalue())


def plot(runs: list[dict], envs: list[str], controllers: list[str], out: Path) -> list[Path]:
    """``training.png`` and ``test_returns.png`` (module docstring)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    cols = min(3, len(envs))
    rows = math.ceil(len(envs) / cols)
    written = []
    for name in ("training", "test_returns"):
        fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.3 * rows), squeeze=False)
        for ax in axes.flat[len(envs):]:
            ax.set_visible(False)
        for ax, env in zip(axes.flat, envs, strict=False):
            threshold = ENVIRONMENTS[env].threshold
            ax.axhline(threshold, color="k", ls="--", lw=1, label=f"threshold {threshold:g}")
            for ci, controller in enumerate(controllers):
                rs = [r for r in runs if r["env"] == env and r["controller"] == controller]
                color = COLORS[controller]
                if name == "training":
                    for k, r in enumerate(rs):
                        ax.plot(range(1, len(r["history"]) + 1), r["history"], color=color, lw=1, alpha=0.8,
                                marker="o", ms=2.5, label=LABELS[controller] if k == 0 else None)
                    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
                    ax.set_xlim(0.5, max([2, *(len(r["history"]) for r in runs if r["env"] == env)]) + 0.5)
                    ax.set_xlabel("generation")
                    ax.set_ylabel("best training fitness")
                else:
                    x = [ci + 0.08 * (k - (len(rs) - 1) / 2) for k in range(len(rs))]
                    ax.scatter(x, [r["test_mean"] for r in rs], color=color, s=28, zorder=3,
                               label="test mean" if ci == 0 else None)
                    ax.scatter(x, [r["test_worst"] for r in rs], color=color, marker="x", s=22, zorder=3,
                               label="test worst" if ci == 0 else None)
            if name == "test_returns":
                ax.set_xticks(range(len(controllers)), [LABELS[c] for c in controllers])
                ax.set_xlim(-0.6, len(controllers) - 0.4)
                ax.set_ylabel("return (champion, test episodes)")
            ax.set_title(env, fontsize=10)
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
        title = ("Best training fitness per generation (each line a run)" if name == "training"
                 else "Each run's champion on the test episodes: mean (dot) and worst (x)")
        fig.suptitle(title, fontsize=11)
        fig.tight_layout()
        written.append(_save_png(fig, out / f"{name}.png"))
        plt.close(fig)
    return written


def write_results(results: dict, out: Path) -> list[Path]:
    """``runs.csv``, ``results.json``, the plots, then ``summary.md`` (last: the report is complete)."""
    out.mkdir(parents=True, exist_ok=True)
    runs = results["runs"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=CSV_FIELDS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for r in runs:
        writer.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})
    written = [atomic_write_bytes(out / "runs.csv", buf.getvalue().encode())]
    written.append(atomic_write_bytes(out / "results.json", (json.dumps(results, indent=1) + "\n").encode()))
    settings = results["settings"]
    written += plot(runs, settings["envs"], settings["controllers"], out)
    md = (f"# Classic control: NEAT-SNN and sigmoid NEAT ({results['date']})\n\n`{results['command']}`\n\n"
          + summary_markdown(results["summary"], settings["test_episodes"]))
    written.append(atomic_write_bytes(out / "summary.md", md.encode()))
    return written


def _int_at_least(low: int, what: str):
    """An argparse type: an int of at least ``low`` (``what`` names it in the error)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = low - 1
        if value < low:
            raise argparse.ArgumentTypeError(f"must be a {what} integer, got {text!r}")
        return value
    return parse


_positive, _seed = _int_at_least(1, "positive"), _int_at_least(0, "non-negative")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m experiments.classic_control", description=__doc__.split("\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=list(ENVIRONMENTS), choices=list(ENVIRONMENTS), metavar="ENV",
                   help=f"environments (default: all; from {', '.join(ENVIRONMENTS)})")
    p.add_argument("--controllers", nargs="+", default=list(CONTROLLERS), choices=CONTROLLERS,
                   help="controllers (default: both)")
    p.add_argument("--seeds", nargs="+", type=_seed, default=list(SEEDS), help="run seeds (default: 0 1 2 3 4)")
    p.add_argument("--generations", type=_positive, default=None,
                   help="generation budget of every run (default: each environment's)")
    p.add_argument("--episodes", type=_positive, default=None,
                   help="fresh training episodes per genome per generation (default: the library's, 16)")
    p.add_argument("--pop-size", type=_positive, default=150)
    p.add_argument("--validation-episodes", type=_positive, default=VALIDATION_EPISODES)
    p.add_argument("--test-episodes", type=_positive, default=100)
    p.add_argument("--out", default="results/classic_control")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    for name in ("envs", "controllers", "seeds"):
        values = getattr(args, name)
        if len(set(values)) != len(values):
            p.error(f"--{name} repeats a value: {' '.join(map(str, values))}")
    if args.pop_size < 2:
        p.error(f"--pop-size must be at least 2, got {args.pop_size}")
    return args


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    torch.set_num_threads(1)
    from tqdm.auto import tqdm

    command = "python -m experiments.classic_control " + shlex.join(sys.argv[1:] if argv is None else argv)
    plan = [(env, controller, seed, args.generations or ENVIRONMENTS[env].generations,
             args.episodes)
            for env in args.envs for controller in args.controllers for seed in args.seeds]
    bar = tqdm(total=sum(p[3] for p in plan), unit="gen", disable=args.quiet, file=sys.stderr)
    runs = []
    t0 = time.perf_counter()
    for env, controller, seed, generations, episodes in plan:
        bar.set_description(f"{env} {controller} seed {seed}")
        runs.append(evolve_run(env, controller, seed, generations=generations, episodes=episodes,
                               pop_size=args.pop_size, validation_episodes=args.validation_episodes,
                               test_episodes=args.test_episodes, progress=bar))
    bar.close()
    settings = {
        "envs": args.envs, "controllers": args.controllers, "seeds": args.seeds, "pop_size": args.pop_size,
        "validation_episodes": args.validation_episodes, "test_episodes": args.test_episodes,
        "validation_seed": f"{VALIDATION_SEED} + seed", "test_seed": f"{TEST_SEED} + seed",
        "environments": {env: {**asdict(ENVIRONMENTS[env]),
                               "generations": args.generations or ENVIRONMENTS[env].generations,
                               "episodes": args.episodes or RANDOM_START_EPISODES} for env in args.envs},
        "specs": {f"{env} {c}": repr(controller_spec(env, c)) for env in args.envs for c in args.controllers},
        "ga": TASK_GA,
        "confirm_candidates": CONFIRM_CANDIDATES, "final_candidates": FINAL_CANDIDATES,
    }
    results = {"date": datetime.date.today().isoformat(), "command": command, "settings": settings,
               "wall_s": round(time.perf_counter() - t0, 1), "summary": summarize(runs), "runs": runs}
    out = Path(args.out)
    write_results(results, out)
    if not args.quiet:
        print(summary_markdown(results["summary"], args.test_episodes))
        print(f"wrote {out}/: runs.csv, results.json, summary.md, training.png, test_returns.png")
    return results


if __name__ == "__main__":
    main()
