"""The report of the paper's Tables I and II: the table beside the paper's rows, the U-test, Fig. 8,
an example trajectory and topology per controller, every champion genome, and (Table II) the
625-start generalisation test.

Written by ``snn-neat reproduce table1|table2`` (``tasks.studies.registry.STUDIES[...].write_report``).
"""

from __future__ import annotations

import os
import statistics
from pathlib import Path

from tasks.studies.results import (
    LABELS,
    ControllerRuns,
    ReportWriter,
    example_label,
    example_run,
    mann_whitney,
)

__all__ = ["PAPER", "summarize", "format_markdown", "write_table_report"]

# [Qiu19] Tables I and II (failures counted as 101 generations in median and mean).
PAPER = {
    "table1": {"sigmoid": {"best": 3, "worst": 55, "median": 17.5, "mean": 21.68, "failures": 1, "runs": 60},
               "snn": {"best": 1, "worst": 92, "median": 9.5, "mean": 16.55, "failures": 1, "runs": 60}},
    "table2": {"sigmoid": {"best": 8, "worst": 96, "median": 44, "mean": 50.35, "failures": 7, "runs": 60},
               "snn": {"best": 5, "worst": 65, "median": 21.5, "mean": 24.70, "failures": 0, "runs": 60}},
}


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
        lines.append("GA settings (tasks/studies/registry.py, GA_PRESETS and each study's tuned_ga): " + "; ".join(ga) + ".")
    if any(row.get("coding") == "signed" for row in summary["rows"].values()):
        lines.append("Input coding: signed (`--coding signed`, a sensitivity study, not the paper's): each observation "
                     "in [-1, 1] over the paper's bounds, centred; the Bernoulli encoder's as push-pull pairs of input "
                     "neurons (tasks/studies/cartpole.py, paper_spec).")
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
    from tasks.studies import cartpole as cp

    one = r.champions.select_runs([run])
    steps = None if task == "table2" else MARKOV_RECORD_STEPS
    plant_task = cp.paper_task(task, max_steps=steps)
    spec = cp.paper_spec(task, r.controller, r.extra.get("coding", "study"))  # the coding it evolved with
    controller = make_controller(one, r.config, plant_task, spec)
    trace = rollout(plant_task, controller, record=True).trace
    state = trace["state"][:, 0]
    out = {"x": state[:, 0], "theta": state[:, 2], "force": trace["action"][:, 0, 0],
           "activity": trace["activity"][:, 0],
           "nodes": controller.nodes if r.controller == "snn" else None}
    return out, plant_task.control_period_s


def _generalization(r: ControllerRuns) -> list[float]:
    from tasks.studies.cartpole import paper_spec
    from tasks.studies.generalization import success_rate

    spec = paper_spec("table2", r.controller, r.extra.get("coding", "study"))  # the coding it evolved with
    rate = success_rate(r.champions, r.config, controller=r.controller, spec=spec)  # [R, 1]
    return rate[:, 0].tolist()


def write_table_report(results: dict[str, ControllerRuns], table: str, out: str | os.PathLike, *, command: str,
                       generalization: bool = True) -> list[Path]:
    """Write the table (Markdown, CSV), per-run CSV, summary JSON, Fig. 8, an example
    trajectory and topology per controller, and every champion genome (``ReportWriter``: a
    report that has ``TABLE.md`` is complete). Returns the paths."""
    import csv
    import io

    from evolution.plots import plot_best_fitness_mean_std, plot_topology
    from tasks.studies.plots import plot_episode, plot_trajectory

    report = ReportWriter(out, table)
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
    report.text(f"{table}.csv", buf.getvalue())

    def runs_rows():
        for c, r in results.items():
            hidden, conns = r.champion_sizes()
            gen = r.extra.get("generalization", [""] * len(r.seeds))
            for i, seed in enumerate(r.seeds):
                yield [c, i, seed, r.solved_generation[i], r.counted()[i], r.best_fitness[i], int(hidden[i]),
                       int(conns[i]), gen[i]]

    report.rows("runs.csv", ["controller", "run", "seed", "solved_generation", "counted_generations", "best_fitness",
                             "hidden_nodes", "enabled_connections", "generalization"], runs_rows())

    target = float(next(iter(results.values())).config.fitness_threshold)
    report.png(plot_best_fitness_mean_std({LABELS.get(c, c): r.history.T for c, r in results.items()},
                                          max_fitness=target,
                                          title=f"Best fitness per generation over {len(seeds)} runs (Fig. 8)"),
               "fig8_best_fitness.png")
    for c, r in results.items():
        run = example_run(r)
        label = example_label(r, run)
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
        report.png(fig, f"trajectory_{c}.png")
        names = {**inputs, r.config.first_output: "F"}
        report.png(plot_topology(r.champions, r.config, run, 0, labels=names, title=f"Champion topology: {label}"),
                   f"topology_{c}.png")
    report.champions(results)
    return report.finish(summary, md)
