"""``snn-neat evolve ENV``'s outputs, each written atomically into ``OUT``:

* ``champions/seed<S>.json``: each run's champion genome (``evolution.load_genome`` reads it
  with the config recorded in ``results.json``); its ``fitness`` is the champion's mean on the
  held-out episodes it was picked on.
* ``learning_curve.png``: per run (one colour each) the best training fitness per generation,
  the held-out checks (x: the best checked genome's held-out mean, in the generations that
  reached the threshold in training) and the champion's test mean (a star, after its last
  generation); the threshold as a dashed line.
* ``results.json`` (written last: its presence marks a complete report): the command, every
  setting (ENV, the task, the controller and its resolved spec, the NEATConfig as a dict, seeds,
  budget, threshold and its source, held-out and test episodes and seeds), a summary, and per run
  its record (``tasks.studies.threshold_runs.RunRecord``: ``confirmed_generation`` is the
  generation it reached the threshold in, ``episodes`` the training episodes it used,
  ``confirmed_cpu_s`` / ``confirmed_wall_s`` the seconds to it, ``history`` the best training
  fitness per generation; ``reached_threshold``: its champion's test mean at or above the
  threshold, None without one). Non-finite numbers are written as the strings "inf", "-inf", "nan".

``summary_table`` is the table the command prints.
"""

from __future__ import annotations

import datetime
import io
import json
import math
import os
import statistics
from dataclasses import asdict
from pathlib import Path

from evolution.checkpoint import atomic_write_bytes
from evolution.genome_io import save_genome
from tasks.studies.evolve_env import EnvRuns
from tasks.studies.threshold_runs import (
    CONFIRM_CANDIDATES,
    FINAL_CANDIDATES,
    TEST_SEED,
    VALIDATION_EPISODES,
    VALIDATION_SEED,
    RunRecord,
)

__all__ = ["TIMING_FIELDS", "results_dict", "summary_table", "write_report"]

LABELS = {"snn": "NEAT-SNN", "sigmoid": "sigmoid NEAT"}
# what differs between an interrupted and resumed run and an uninterrupted one
TIMING_FIELDS = ("cpu_s", "wall_s", "train_cpu_s", "train_wall_s", "confirmed_cpu_s", "confirmed_wall_s")


def _finite(value):
    """``value`` with non-finite floats as strings, recursively (strict JSON has no inf or NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _reached(r: RunRecord, threshold: float | None) -> bool | None:
    return None if threshold is None or r.test_mean is None else r.test_mean >= threshold


def _median(values: list) -> float | None:
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def champion_name(seed: int) -> str:
    return f"champions/seed{seed}.json"


def results_dict(runs: EnvRuns, command: str) -> dict:
    """``results.json``'s content (module docstring)."""
    plan, built = runs.plan, runs.built
    thr = built.threshold
    reached = [r for r in runs.records if _reached(r, thr)]
    confirmed = [r for r in runs.records if r.confirmed_generation > 0]
    per_run = [{**asdict(r), "reached_threshold": _reached(r, thr), "champion": champion_name(r.seed)}
               for r in runs.records]
    return _finite({
        "command": command,
        "date": datetime.date.today().isoformat(),
        "env": plan.env, "kind": built.resolved.kind, "task": repr(built.resolved.task),
        "controller": plan.controller, "spec": repr(built.fitness.spec), "config": built.config.to_dict(),
        "seeds": list(plan.seeds), "fitness_seed": plan.seeds[0],
        "budget": {"generations": built.generations, "episodes": plan.episodes,
                   "asked": "episodes" if plan.episodes is not None else "generations"},
        "pop_size": built.config.pop_size, "episodes_per_genome": built.episodes_per_genome,
        "threshold": thr, "threshold_source": built.threshold_source,
        "held_out": {"episodes": VALIDATION_EPISODES, "seed": f"{VALIDATION_SEED} + seed",
                     "candidates": CONFIRM_CANDIDATES, "final_candidates": FINAL_CANDIDATES},
        "test": {"episodes": runs.records[0].test_episodes, "seed": f"{TEST_SEED} + seed"},
        "device": plan.device, "shards": runs.shards,
        "summary": {
            "runs": len(runs.records), "confirmed": len(confirmed),
            "reached_threshold": None if thr is None else len(reached),
            "median_test_mean": _median([r.test_mean for r in runs.records]),
            "median_confirmed_generation": _median([r.confirmed_generation for r in confirmed]),
            "median_episodes_to_threshold": _median([r.confirmed_episodes for r in confirmed]),
            "median_cpu_s_to_threshold": _median([r.confirmed_cpu_s for r in confirmed]),
            "cpu_s": sum(r.cpu_s for r in runs.records),
        },
        "wall_s": runs.wall_s,
        "runs": per_run,
    })


def _fmt(value, digits: int = 1) -> str:
    if value is None:
        return "-"
    return f"{value:,.{digits}f}" if isinstance(value, float) else f"{value:,}"


def _score_digits(threshold: float | None, scores: list[float | None]) -> int:
    """Decimals that tell a score from the threshold: 1 where returns run to tens or more, 3
    where they are fractions (FrozenLake-v1's 0.69 against 0.70 would both print 0.7)."""
    scale = max([abs(v) for v in (threshold, *scores) if v is not None] or [0.0])
    return 1 if scale >= 10.0 else 3


def summary_table(runs: EnvRuns) -> str:
    """One row per run, then a line on the threshold."""
    thr = runs.built.threshold
    d = _score_digits(thr, [r.test_mean for r in runs.records])
    lines = ["| seed | generations | confirmed at | training episodes | CPU s to threshold | test mean | test worst "
             "| test std | reached |", "|---|---|---|---|---|---|---|---|---|"]
    for r in runs.records:
        reached = _reached(r, thr)
        lines.append(f"| {r.seed} | {r.generations} | {r.confirmed_generation if r.confirmed_generation > 0 else '-'} "
                     f"| {_fmt(r.episodes)} | {_fmt(r.confirmed_cpu_s, 2)} | {_fmt(r.test_mean, d)} | {_fmt(r.test_worst, d)} "
                     f"| {_fmt(r.test_std, d)} | {'-' if reached is None else ('yes' if reached else 'no')} |")
    label = LABELS.get(runs.plan.controller, runs.plan.controller)
    episodes = runs.records[0].test_episodes
    if thr is None:
        lines.append(f"{runs.plan.env}, {label}: no threshold (give --threshold); test means over {episodes} episodes")
    else:
        n = sum(bool(_reached(r, thr)) for r in runs.records)
        lines.append(f"{runs.plan.env}, {label}: {n}/{len(runs.records)} runs reached {thr:g} "
                     f"({runs.built.threshold_source}) on {episodes} test episodes")
    return "\n".join(lines) + "\n"


def plot_learning_curve(runs: EnvRuns, path: str | os.PathLike) -> Path:
    """``learning_curve.png`` (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    colors = plt.get_cmap("tab10" if len(runs.records) <= 10 else "viridis")
    for k, r in enumerate(runs.records):
        color = colors(k % 10 if len(runs.records) <= 10 else k / max(1, len(runs.records) - 1))
        gens = range(1, r.generations + 1)
        ax.plot(gens, r.history, color=color, lw=1.2, marker="o", ms=2.5, label=f"seed {r.seed}" if len(runs.records) <= 10 else None)
        checked = [(g, c) for g, c in zip(gens, r.checks, strict=True) if c is not None]
        if checked:
            ax.scatter(*zip(*checked, strict=True), color=color, marker="x", s=28, zorder=3)
        if r.test_mean is not None:
            ax.scatter([r.generations + 0.5], [r.test_mean], color=color, marker="*", s=70, zorder=4)
    if runs.built.threshold is not None:
        ax.axhline(runs.built.threshold, color="k", ls="--", lw=1, label=f"threshold {runs.built.threshold:g}")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("generation")
    what = "return" if runs.built.resolved.task.fitness == "return" else "steps"
    ax.set_ylabel(f"best training fitness ({what})")
    label = LABELS.get(runs.plan.controller, runs.plan.controller)
    ax.set_title(f"{runs.plan.env}, {label}: line best training fitness, x held-out check, * champion's test mean",
                 fontsize=9)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())


def write_report(runs: EnvRuns, out: str | os.PathLike, command: str) -> list[Path]:
    """Every output of the module docstring; ``results.json`` is removed first and written last."""
    out = Path(out)
    (out / "results.json").unlink(missing_ok=True)
    written = [save_genome(out / champion_name(r.seed), runs.champions, runs.built.config, run=k, index=0,
                           fitness=r.champion_validation) for k, r in enumerate(runs.records)]
    written.append(plot_learning_curve(runs, out / "learning_curve.png"))
    text = json.dumps(results_dict(runs, command), indent=1, allow_nan=False) + "\n"
    written.append(atomic_write_bytes(out / "results.json", text.encode()))
    return written
