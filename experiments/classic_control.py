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
``test_reaches`` says whether the test mean meets the threshold.

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
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from evolution import (
    NEAT,
    Genomes,
    SigmoidSpec,
    SpikingSpec,
    TaskFitness,
    make_controller,
    rollout,
    task_config,
)
from evolution.checkpoint import atomic_write_bytes
from tasks.gym_adapter import GymTask
from tasks.studies.registry import ga_overrides

__all__ = ["ENVIRONMENTS", "CONTROLLERS", "EnvSetting", "controller_spec", "make_task", "evolve_run", "main"]


@dataclass(frozen=True)
class EnvSetting:
    """One environment's study settings: gymnasium's reward ``threshold``, the generation budget,
    training episodes per genome per generation, and ``GymTask`` options."""

    threshold: float
    generations: int
    episodes: int
    task_options: dict = field(default_factory=dict)
    note: str = ""


# Generation budgets sized from a pilot (seconds per generation of 150 genomes x 16 episodes on one
# CPU thread: NEAT-SNN about 6 on Acrobot, 2.3 on Pendulum, under 1 elsewhere; sigmoid NEAT about
# a tenth) to fit the whole study (50 runs) in well under 30 minutes (docs/classic-control.md).
ENVIRONMENTS: dict[str, EnvSetting] = {
    "CartPole-v1": EnvSetting(
        475.0, 50, 16, {"observation_bounds": ((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))},
        "x and theta coded over the termination limits, the velocities over +-3 m/s and +-3.5 rad/s"),
    "Acrobot-v1": EnvSetting(
        -100.0, 30, 16, {"control_period_s": 0.05},
        "NEAT-SNN runs 50 ms of network time per 0.2 s plant step (100 substeps, not 400)"),
    "MountainCar-v0": EnvSetting(-110.0, 100, 16),
    "MountainCarContinuous-v0": EnvSetting(90.0, 30, 16),
    "Pendulum-v1": EnvSetting(-200.0, 50, 16),
}
CONTROLLERS = ("snn", "sigmoid")
SEEDS = (0, 1, 2, 3, 4)
# the study's GA (the double pole's pick for both controllers, tasks.studies.registry.STUDIES["dpv"].tuned_ga)
GA = {**ga_overrides("neat-python"), "survival_threshold": 0.1, "max_hidden": 16}
CONFIRM_CANDIDATES = 5  # genomes reaching the threshold in training checked on the held-out episodes
FINAL_CANDIDATES = 20  # of the final generation, re-evaluated when no genome was confirmed
VALIDATION_SEED, TEST_SEED = 20_000_000, 10_000_000  # + the run's seed


def controller_spec(controller: str) -> SpikingSpec | SigmoidSpec:
    """Both controllers code observations signed about the middle of their bounds. NEAT-SNN: rates
    over one control step (``rate_window_steps=1``), counted from rest (``rest_relative``)."""
    if controller == "snn":
        return SpikingSpec(input_coding="signed", rate_window_steps=1, rest_relative=True)
    if controller == "sigmoid":
        return SigmoidSpec(input_coding="signed")
    raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")


def make_task(env_id: str):
    """The torch port of ``env_id`` with the study's options."""
    return GymTask(env_id, **ENVIRONMENTS[env_id].task_options)


def _cat(a: Genomes, b: Genomes) -> Genomes:
    return Genomes(**{k: torch.cat([v, getattr(b, k)], 1) for k, v in a.tensors().items()})


def _returns(task, genomes: Genomes, config, spec, episodes: int, seed: int) -> torch.Tensor:
    """``[G, episodes]`` returns of the ``[1, G]`` genomes on ``episodes`` episodes seeded by ``seed``."""
    return rollout(task, make_controller(genomes, config, task, spec), episodes=episodes, seed=seed).returns


def evolve_run(env_id: str, controller: str, seed: int, *, generations: int, episodes: int, pop_size: int,
               validation_episodes: int, test_episodes: int, progress=None) -> dict:
    """One run; returns its record (see the module docstring)."""
    setting = ENVIRONMENTS[env_id]
    threshold = setting.threshold
    task, spec = make_task(env_id), controller_spec(controller)
    config = task_config(task, spec, pop_size=pop_size, fitness_threshold=threshold, **GA)
    fitness = TaskFitness(task, config, spec=spec, episodes=episodes, seed=seed, fresh_starts=True)
    neat = NEAT(config, seeds=[seed])
    validation_seed = VALIDATION_SEED + seed
    history: list[float] = []
    train_gen, train_evals, train_wall = -1, 0, 0.0
    confirmed_gen, champion, champion_validation = -1, None, None
    evaluations = validation_evaluations = 0
    last = last_f = None
    # one tiny rollout first, so the run's wall time does not include loading or compiling kernels
    rollout(task, make_controller(neat.ask().gather(torch.zeros(1, 1, dtype=torch.long)), config, task, spec),
            episodes=1, max_steps=2)
    t0 = time.perf_counter()
    for gen in range(1, generations + 1):
        genomes = neat.ask()
        f = fitness(genomes)  # [1, P]
        last, last_f = genomes.clone(), f.clone()  # tell() breeds the next generation in place of these
        evaluations += pop_size * episodes
        best = float(f.max())
        history.append(best)
        solved = torch.zeros_like(f, dtype=torch.bool)
        if best >= threshold:
            if train_gen < 0:
                train_gen, train_evals, train_wall = gen, evaluations, time.perf_counter() - t0
            k = min(CONFIRM_CANDIDATES, int((f >= threshold).sum()))
            idx = f[0].topk(k).indices
            candidates = genomes.gather(idx.unsqueeze(0))
            val = _returns(task, candidates, config, spec, validation_episodes, validation_seed).mean(1)
            validation_evaluations += k * validation_episodes
            passed = val >= threshold
            if bool(passed.any()):
                solved[0, idx[passed]] = True
                pick = int(torch.where(passed, val, -math.inf).argmax())
                confirmed_gen, champion_validation = gen, float(val[pick])
                champion = candidates.gather(torch.tensor([[pick]]))
        neat.tell(f, solved)
        if progress is not None:
            progress.update(1)
            progress.set_postfix(best=f"{best:.1f}", refresh=False)
        if confirmed_gen > 0:
            break
    generations_run = len(history)
    if progress is not None and generations_run < generations:
        progress.update(generations - generations_run)
    if champion is None:  # none confirmed: the best on the held-out episodes of the last fittest and the best-ever
        top = last_f[0].topk(min(FINAL_CANDIDATES, pop_size)).indices.unsqueeze(0)
        candidates = _cat(last.gather(top), neat.result().best_genomes)
        val = _returns(task, candidates, config, spec, validation_episodes, validation_seed).mean(1)
        validation_evaluations += candidates.pop_size * validation_episodes
        pick = int(val.argmax())
        champion, champion_validation = candidates.gather(torch.tensor([[pick]])), float(val[pick])
    test = _returns(task, champion, config, spec, test_episodes, TEST_SEED + seed)[0]
    wall = time.perf_counter() - t0
    if train_gen < 0:
        train_evals, train_wall = evaluations, wall
    test_mean = float(test.mean())
    return {"env": env_id, "controller": controller, "seed": seed, "threshold": threshold,
            "train_generation": train_gen, "evaluations": train_evals, "wall_s": round(train_wall, 2),
            "confirmed_generation": confirmed_gen, "generations_run": generations_run,
            "total_evaluations": evaluations, "validation_evaluations": validation_evaluations,
            "total_wall_s": round(wall, 2), "best_training_fitness": max(history),
            "champion_validation_mean": champion_validation,
            "test_mean": test_mean, "test_worst": float(test.min()), "test_reaches": test_mean >= threshold,
            "champion_hidden": int(champion.num_hidden(config)[0, 0]),
            "champion_genes": int(champion.num_genes()[0, 0]), "history": history}


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
                   help="fresh training episodes per genome per generation (default: each environment's)")
    p.add_argument("--pop-size", type=_positive, default=150)
    p.add_argument("--validation-episodes", type=_positive, default=32)
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
             args.episodes or ENVIRONMENTS[env].episodes)
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
                               "episodes": args.episodes or ENVIRONMENTS[env].episodes} for env in args.envs},
        "specs": {c: repr(controller_spec(c)) for c in args.controllers}, "ga": GA,
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
