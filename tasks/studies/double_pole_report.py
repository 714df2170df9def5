"""The double-pole study's report: evaluations to solve beside the published figures, the
625-start generalisation test, champion sizes and the memory ablation, with plots.

Written by ``snn-neat reproduce dpv|dpnv`` (``tasks.studies.registry.STUDIES[...].write_report``).
"""

from __future__ import annotations

import math
import os
import statistics
import time
from collections.abc import Sequence
from pathlib import Path

from tasks.studies.double_pole import (
    GENERALIZATION_PASS,
    GENERALIZATION_STARTS,
    LONG_BALANCE_STEPS,
    NEAT121_SCALES,
    PUBLISHED,
    PUSH_PULL_INPUT_NA,
    study_spec,
    study_task,
)
from tasks.studies.generalization import GENERALIZATION_STEPS, generalization_starts
from tasks.studies.neat121_runs import compare_with_neat121
from tasks.studies.results import (
    LABELS,
    ControllerRuns,
    ReportWriter,
    example_label,
    example_run,
    mann_whitney,
)

__all__ = ["study_rows", "write_study_report", "STATIC_MAP_STEPS", "neat121_evaluations", "neat121_counts"]

EPISODE_PLOT_STEPS = 1000  # control steps of a champion's episode drawn in trajectory_*.png
STATIC_MAP_STEPS = 20  # control steps (400 ms) a fresh network settles on each observation in the ablation


def _champion_tests(r: ControllerRuns, variant: str, generalization: bool) -> dict[str, list[float]]:
    """Per run: starts of the 625 its champion balances for 1000 steps, and steps balanced from the
    standard start (up to 1000), each as evolved and as a static map."""
    from tasks.studies.generalization import balanced_steps

    coding = r.extra.get("coding", "study")
    task, spec = study_task(variant, coding), study_spec(variant, r.controller, coding)
    out: dict[str, list[float]] = {}
    if not generalization:
        return out
    starts = generalization_starts()
    for name, settle in (("generalization", None), ("generalization_static_map", STATIC_MAP_STEPS)):
        steps = balanced_steps(r.champions, r.config, spec, starts=starts, task=task,
                               static_map_steps=settle)
        out[name] = (steps[:, 0] >= GENERALIZATION_STEPS).sum(-1).tolist()
    for name, settle in (("standard_start", None), ("standard_start_static_map", STATIC_MAP_STEPS)):
        steps = balanced_steps(r.champions, r.config, spec, task=task, static_map_steps=settle)
        out[name] = steps[:, 0, 0].tolist()
    return out


def _mean(values: list[float]) -> float:
    return statistics.mean(values) if values else math.nan


def study_rows(results: dict[str, ControllerRuns], variant: str, *, generalization: bool = True) -> dict:
    """Each controller's row (evaluations to solve, failures, generalisation, sizes, ablation) and
    the per-run columns, as one JSON-able dict; the U-test of evaluations when both ran."""
    rows, per_run = {}, {}
    for c, r in results.items():
        pop = r.config.pop_size
        solved = [g > 0 for g in r.solved_generation]
        evals = [g * pop for g in r.counted()]  # a failure counts as (budget + 1) x population
        solved_evals = [e for e, s in zip(evals, solved, strict=True) if s]
        neat121 = neat121_evaluations(r)
        neat121_solved = [e for e in neat121 if e is not None]
        hidden, conns = r.champion_sizes()
        start = time.process_time()
        tests = _champion_tests(r, variant, generalization)
        report_tests_cpu_s = time.process_time() - start
        per_run[c] = {"seed": r.seeds, "solved_generation": r.solved_generation, "evaluations": evals,
                      "evaluations_neat121": ["" if e is None else e for e in neat121],
                      "best_fitness": r.best_fitness, "hidden_nodes": hidden, "enabled_connections": conns, **tests}
        row = {"controller": c, "runs": len(evals), "solved": sum(solved), "failures": len(evals) - sum(solved),
               "population": pop, "generations": r.generations,
               "evaluations_mean_solved": _mean(solved_evals),
               "evaluations_median_solved": statistics.median(solved_evals) if solved_evals else math.nan,
               "evaluations_best": min(solved_evals) if solved_evals else math.nan,
               "evaluations_worst": max(solved_evals) if solved_evals else math.nan,
               "evaluations_mean_all": _mean(evals), "wall_s": r.wall_s, "ga": r.extra.get("ga", ""),
               "cpu_s": r.extra.get("cpu_s", math.nan), "solve_test_cpu_s": r.extra.get("solve_test_cpu_s", math.nan),
               "report_tests_cpu_s": report_tests_cpu_s,
               "evaluations_neat121_mean_solved": _mean(neat121_solved),
               "evaluations_neat121_median_solved": statistics.median(neat121_solved) if neat121_solved else math.nan}
        if r.extra.get("setup") is not None:
            row["setup"] = r.extra["setup"]
        if r.extra.get("coding", "study") != "study":
            row["coding"] = r.extra["coding"]
        if r.extra.get("champion_test", "champion") != "champion":
            row["champion_test"] = r.extra["champion_test"]
        if r.extra.get("fitness_starts", 1) != 1:
            row["fitness_starts"] = r.extra["fitness_starts"]
        if r.extra.get("fitness", "study") != "study":
            row["fitness"] = r.extra["fitness"]
        if r.extra.get("min_general") is not None:
            row["min_general"] = r.extra["min_general"]
        for key, values in (("hidden_nodes", hidden), ("connections", conns), *(
                (k, tests[k]) for k in ("generalization", "generalization_static_map") if k in tests)):
            row[f"{key}_mean_all"] = _mean(values)
            row[f"{key}_mean_solved"] = _mean([v for v, s in zip(values, solved, strict=True) if s])
        for key, name in (("standard_start", "holds_1000_steps"),
                          ("standard_start_static_map", "static_map_holds_1000_steps")):
            if key in tests:
                row[name] = sum(s >= GENERALIZATION_STEPS for s in tests[key])
        rows[c] = row
    out = {"variant": variant, "rows": rows, "runs": per_run, "published": PUBLISHED[variant],
           "against_neat121": {c: compare_with_neat121(neat121_evaluations(r), variant) for c, r in results.items()}}
    if "snn" in results and "sigmoid" in results:
        out["mann_whitney_u"] = mann_whitney(per_run["snn"]["evaluations"], per_run["sigmoid"]["evaluations"])
    return out


def neat121_evaluations(r: ControllerRuns) -> list[int | None]:
    """Per run, evaluations to solve as NEAT C++ 1.2.1 counts them: ``pop_size * (generation - 1)``
    plus the 1-based position of the first solving genome in its generation; None for a run that
    did not solve, or whose position was not recorded (results from before it was kept)."""
    positions = r.extra.get("solved_position") or [-1] * len(r.solved_generation)
    return neat121_counts(r.config.pop_size, r.solved_generation, positions)


def neat121_counts(pop_size: int, solved_generation: Sequence[int], solved_position: Sequence[int]) -> list[int | None]:
    """``neat121_evaluations`` from NEAT's per-run records (``NEAT.solved_generation``,
    ``NEAT.solved_position``, as lists): ``pop_size * (generation - 1) + position + 1``, or None."""
    return [pop_size * (g - 1) + q + 1 if g > 0 and q >= 0 else None
            for g, q in zip(solved_generation, solved_position, strict=True)]


def _fmt(value: float, digits: int = 0) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:,.{digits}f}"


def _pair(row: dict, key: str, digits: int = 1) -> str:
    """``"mean over all runs / mean over solved runs"`` of ``key``."""
    return f"{_fmt(row.get(key + '_mean_all', math.nan), digits)} / {_fmt(row.get(key + '_mean_solved', math.nan), digits)}"


def format_study_markdown(summary: dict, command: str) -> str:
    """The study's tables: ours beside the published rows, then generalisation, sizes, ablation."""
    variant = summary["variant"]
    title = {"dpv": "Double-pole balancing with velocities (DPV)",
             "dpnv": "Double-pole balancing without velocities (DPNV, damping fitness)"}[variant]
    seeds = summary["seeds"]
    lines = [f"# {title}", "", f"Command: `{command}`", f"Seeds: {seeds[0]}..{seeds[-1]} ({len(seeds)} runs per controller)", "",
             "| Method | Source | Population | Evaluations to solve (mean over solved runs) | Median | Best | Worst | "
             "Failures | Generalisation (of 625) | NEAT 1.2.1's count: mean | median |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c, row in summary["rows"].items():
        gen = row.get("generalization_mean_solved")
        lines.append(f"| {LABELS.get(c, c)} | this code | {row['population']:,} | {_fmt(row['evaluations_mean_solved'])} | "
                     f"{_fmt(row['evaluations_median_solved'])} | {_fmt(row['evaluations_best'])} | "
                     f"{_fmt(row['evaluations_worst'])} | {row['failures']}/{row['runs']} | "
                     f"{_fmt(gen, 1) if gen is not None else '-'} | "
                     f"{_fmt(row.get('evaluations_neat121_mean_solved', math.nan))} | "
                     f"{_fmt(row.get('evaluations_neat121_median_solved', math.nan))} |")
    for p in summary["published"]:
        lines.append(f"| {p['method']} | {p['source']} | {_fmt(p.get('population'))} | {_fmt(p.get('evaluations'))} | "
                     f"| | | {p.get('failures', '')} | {p.get('generalization', '-')} | {_fmt(p.get('neat121_mean'))} | "
                     f"{_fmt(p.get('neat121_median'))} |")
    lines += ["", "Setup of each controller (`--setup`; an option given on the command line overrides the setup's):", "",
              "| Controller | Setup | GA | Coding | Test of a generation | Fitness starts | Fitness | Test of a solution "
              "(of 625 starts) | Budget |", "|---|---|---|---|---|---|---|---|---|"]
    for c, row in summary["rows"].items():
        held = row.get("min_general", GENERALIZATION_PASS) if variant == "dpnv" else "-"
        lines.append(f"| {LABELS.get(c, c)} | {row.get('setup', '-')} | {row['ga']} | {row.get('coding', 'study')} | "
                     f"{row.get('champion_test', 'champion')} | {row.get('fitness_starts', 1)} | "
                     f"{row.get('fitness', 'study')} | {held} | {row['generations']:,} generations of "
                     f"{row['population']:,} ({row['generations'] * row['population']:,} evaluations) |")
    if any(row.get("champion_test") == "species" for row in summary["rows"].values()):
        lines += ["", "Test of a generation: NEAT C++ 1.2.1's, the champion of the best species not tested since its "
                  "last record (the best species when all were), one per run and generation (`--champion-test species`)."]
    for k in sorted({row["fitness_starts"] for row in summary["rows"].values() if "fitness_starts" in row}):
        lines += ["", f"Fitness: the mean damping fitness over {k} episodes, from the standard start and {k - 1} fixed "
                  f"random starts within Gruau's ranges (`--fitness-starts {k}`); one evaluation is one genome of "
                  f"{k} episodes, so a run's episodes are {k} times its evaluations."]
    for n in sorted({row["min_general"] for row in summary["rows"].values() if "min_general" in row}):
        lines += ["", f"Test of a solution: the champion balances {LONG_BALANCE_STEPS:,} steps from the standard start "
                  f"and {n} (not NEAT 2002's {GENERALIZATION_PASS}) of the {GENERALIZATION_STARTS} generalisation "
                  f"starts for {GENERALIZATION_STEPS} steps (`--min-general {n}`): "
                  + ("a stricter test, so the evaluations count to a more general solution." if n > GENERALIZATION_PASS else
                     "a looser test, so the evaluations count to a less general solution.")]
    if any(row.get("fitness") == "damping-both-poles" for row in summary["rows"].values()):
        lines += ["", "Fitness: Gruau's damping fitness with the short pole's angle and angular velocity added to its "
                  "damping term, which sums |x|, |x_dot|, |theta1| and |theta1_dot| over the last 100 steps "
                  "(`--fitness damping-both-poles`)."]
    scales = ", ".join(f"{v:g}" for v in NEAT121_SCALES[variant])
    codings = {  # the sentence for each coding other than the study's own
        "signed": f"signed, as NEAT C++ 1.2.1 feeds its networks: each observed variable divided by its scale "
                  f"({scales}; m, m/s, rad, rad/s), centred and unclipped",
        "push-pull": f"push-pull: each observed variable divided by its scale ({scales}; m, m/s, rad, rad/s) as NEAT "
                     f"C++ 1.2.1 feeds it, unclipped, on two input nodes, its positive and its negative part; "
                     f"NEAT-SNN's input neurons take {PUSH_PULL_INPUT_NA:g} nA per unit"}
    for coding, text in codings.items():
        if any(row.get("coding") == coding for row in summary["rows"].values()):
            lines += ["", f"Input coding: {text} (`--coding {coding}`)."]
    lines += ["", "Evaluations = generations x population, as NEAT 2002 counts them (the champion tests are not "
              "counted); NEAT C++ 1.2.1 counts population x (generation - 1) + the position of the first solving "
              "genome in its generation. A run that does not solve within its budget (the table above) is a failure; the "
              "mean over all runs (failures as the budget + 1 generations) is in summary.json."]
    if "mann_whitney_u" in summary:
        mw = summary["mann_whitney_u"]
        lines.append(f"Mann-Whitney U (two-sided, evaluations, NEAT-SNN vs sigmoid NEAT, failures as budget + 1): "
                     f"U = {mw['U']:g}, p = {mw['p_value']:.3g}.")
    if "against_neat121" in summary:  # summaries written before it was kept lack it
        lines += ["", "Against NEAT C++ 1.2.1's own runs, run by run (its row above; evaluations as NEAT 1.2.1 counts "
                  "them; two-sided tests):", "",
                  "| Controller | Median (solved runs) | NEAT C++ 1.2.1's median | Mann-Whitney U, p (solved runs) | "
                  "Failures | NEAT C++ 1.2.1's failures | Fisher's exact test, p (failures) |", "|---|---|---|---|---|---|---|"]
        for c, cmp in summary["against_neat121"].items():
            p = cmp.get("mann_whitney_p")
            lines.append(f"| {LABELS.get(c, c)} | {_fmt(cmp['median'])} | {_fmt(cmp['neat121_median'])} | "
                         f"{'-' if p is None else f'{p:.3g}'} | {cmp['failures']}/{cmp['runs']} | "
                         f"{cmp['neat121_failures']}/{cmp['neat121_runs']} | {cmp['fisher_p']:.3g} |")
    lines += ["", "Champions of every run (all runs / solved runs):", "",
              "| Controller | Hidden nodes | Connections | Generalisation as evolved | as a static map | "
              f"Hold the standard start {GENERALIZATION_STEPS} steps: as evolved | as a static map | Wall time (s) |",
              "|---|---|---|---|---|---|---|---|"]
    cost = ["", "What the runs cost (CPU seconds, all runs of a controller):", "",
            "| Controller | Evolution | of which the tests of a solution | The report's generalisation and ablation tests |",
            "|---|---|---|---|"]
    for c, row in summary["rows"].items():
        lines.append(f"| {LABELS.get(c, c)} | {_pair(row, 'hidden_nodes', 2)} | {_pair(row, 'connections', 2)} | "
                     f"{_pair(row, 'generalization')} | {_pair(row, 'generalization_static_map')} | "
                     f"{row.get('holds_1000_steps', '-')}/{row['runs']} | "
                     f"{row.get('static_map_holds_1000_steps', '-')}/{row['runs']} | {row['wall_s']:.0f} |")
        cost.append(f"| {LABELS.get(c, c)} | {_fmt(row.get('cpu_s', math.nan))} | "
                    f"{_fmt(row.get('solve_test_cpu_s', math.nan))} | {_fmt(row.get('report_tests_cpu_s', math.nan))} |")
    lines += cost
    lines += ["", f"Generalisation: the 625 start states of Gruau et al. (1996) that a run's champion balances for "
              f"{GENERALIZATION_STEPS} steps (mean). Memory ablation: the same champions run as a "
              f"static map (every control step from the network's initial state, settled {STATIC_MAP_STEPS} control "
              "steps on the current observation; evolution.ablation.StaticMapController)."]
    return "\n".join(lines) + "\n"


def _plot_evaluations(summary: dict):
    """ECDF of evaluations to solve per controller, with the published means as lines."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    for c, runs in summary["runs"].items():
        solved = sorted(e for e, g in zip(runs["evaluations"], runs["solved_generation"], strict=True) if g > 0)
        n = len(runs["evaluations"])
        if solved:
            ax.step(solved, [(i + 1) / n for i in range(len(solved))], where="post", label=f"{LABELS.get(c, c)} ({len(solved)}/{n} solved)")
        else:
            ax.plot([], [], label=f"{LABELS.get(c, c)} (0/{n} solved)")
    for i, p in enumerate(summary["published"]):
        mean, counted = (p["evaluations"], "") if "evaluations" in p else (p["neat121_mean"], ", its own count")
        ax.axvline(mean, color=f"C{i + 2}", ls="--", lw=1, label=f"{p['method']} ({p['source']}): mean{counted}")
    ax.set_xscale("log")
    ax.set_xlabel("evaluations to solve")
    ax.set_ylabel("fraction of runs solved")
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(f"{summary['variant'].upper()}: evaluations to solve over {len(summary['seeds'])} runs")
    return fig


def _plot_generalization(summary: dict):
    """Per controller: starts of 625 balanced by each champion, as evolved and as a static map."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    names, data = [], []
    for c, runs in summary["runs"].items():
        for key, what in (("generalization", "as evolved"), ("generalization_static_map", "static map")):
            if key in runs:
                names.append(f"{LABELS.get(c, c)}\n{what}")
                data.append(runs[key])
    if data:
        ax.boxplot(data)
        ax.set_xticks(range(1, len(names) + 1), names, fontsize=8)
    ax.axhline(GENERALIZATION_PASS, color="grey", ls="--", lw=1, label=f"NEAT 2002's pass mark ({GENERALIZATION_PASS})")
    ax.set_ylabel("starts balanced for 1000 steps (of 625)")
    ax.set_title("Generalisation of every run's champion, and the memory ablation")
    ax.legend(fontsize=8)
    return fig


def _plot_episode(r: ControllerRuns, variant: str, run: int, label: str):
    """Run ``run``'s champion from the standard start for up to 1000 steps, recorded."""
    from evolution.phenotype import make_controller
    from evolution.rollout import rollout
    from tasks.studies.plots import plot_trajectory

    coding = r.extra.get("coding", "study")
    task = study_task(variant, coding).with_fitness("steps", EPISODE_PLOT_STEPS)
    one = r.champions.select_runs([run])
    controller = make_controller(one, r.config, task, study_spec(variant, r.controller, coding))
    trace = rollout(task, controller, record=True).trace
    state, force = trace["state"][:, 0], trace["action"][:, 0, 0]
    return plot_trajectory(state[:, 0], {"θ1 (long pole)": state[:, 2], "θ2 (short pole)": state[:, 4]}, force,
                           tau_s=task.control_period_s, title=f"{label}: the first {len(force)} steps")


def write_study_report(results: dict[str, ControllerRuns], variant: str, out: str | os.PathLike, *, command: str,
                       generalization: bool = True) -> list[Path]:
    """Write VARIANT.md, runs.csv, summary.json, the fitness, evaluations and generalisation plots,
    a champion's topology and episode per controller and every champion genome (``ReportWriter``: a
    report with ``VARIANT.md`` is complete)."""
    from evolution.plots import plot_best_fitness_mean_std, plot_topology

    report = ReportWriter(out, variant)
    summary = study_rows(results, variant, generalization=generalization)
    summary["seeds"] = next(iter(results.values())).seeds
    summary["command"] = command
    keys = ["seed", "solved_generation", "evaluations", "evaluations_neat121", "best_fitness", "hidden_nodes",
            "enabled_connections",
            "generalization", "generalization_static_map", "standard_start", "standard_start_static_map"]
    report.rows("runs.csv", ["controller", "run", *keys],
                ([c, i, *(runs[k][i] if k in runs else "" for k in keys)]
                 for c, runs in summary["runs"].items() for i in range(len(runs["seed"]))))
    report.png(plot_best_fitness_mean_std({LABELS.get(c, c): r.history.T for c, r in results.items()},
                                          title=f"{variant.upper()}: best fitness per generation over "
                                                f"{len(summary['seeds'])} runs"), "best_fitness.png")
    report.png(_plot_evaluations(summary), "evaluations_to_solve.png")
    if generalization:
        report.png(_plot_generalization(summary), "generalization.png")
    names = {i: n for i, n in enumerate(("x", "ẋ", "θ1", "θ̇1", "θ2", "θ̇2") if variant == "dpv" else ("x", "θ1", "θ2"))}
    for c, r in results.items():
        run = example_run(r)
        label = example_label(r, run)
        report.png(plot_topology(r.champions, r.config, run, 0, labels={**names, r.config.first_output: "F"},
                                 title=f"Champion topology: {label}"), f"topology_{c}.png")
        report.png(_plot_episode(r, variant, run, label), f"trajectory_{c}.png")
    report.champions(results)
    return report.finish(summary, format_study_markdown(summary, command))
