"""NEAT's figures: fitness progress over runs (Qiu et al.'s Fig. 8), a genome's topology (Fig. 5),
species sizes, one run's progress with its species, and an EvoTorch weight search's progress.

Every function returns a ``matplotlib.figure.Figure`` built without pyplot, so it works headless
(Agg) and inline in notebooks; ``snn_torch.plots.save_figure`` writes a figure atomically.
``EvolutionHistory`` is a NEAT reporter that records what ``plot_evolution_progress`` draws, one
generation at a time, from the status ``NEAT.tell`` hands its reporters.
"""

from __future__ import annotations

import warnings

import networkx as nx
import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator
from torch import Tensor

from evolution.config import NEATConfig
from evolution.genome_io import to_networkx
from evolution.population import Genomes
from evolution.reporters import BaseReporter, GenerationStatus
from snn_torch.plots import as_numpy as _numpy

__all__ = ["plot_best_fitness_mean_std", "plot_topology", "plot_species_sizes", "plot_evolution_progress",
           "plot_search_progress", "EvolutionHistory"]


def plot_best_fitness_mean_std(curves: dict[str, Tensor | np.ndarray], *, max_fitness: float | None = None,
                               title: str = "") -> Figure:
    """The paper's Fig. 8: best fitness per generation, mean +- standard deviation over runs.

    ``curves[label]`` is ``[runs, generations]``: each run's best fitness per generation.
    NaN entries (a run that stopped early) are left out of that generation's mean and
    standard deviation; fill a solved run forward if it should count at its final value.
    """
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.subplots()
    for label, values in curves.items():
        v = _numpy(values)
        if v.ndim != 2:
            raise ValueError(f"curves[{label!r}] must be [runs, generations], got shape {v.shape}")
        with warnings.catch_warnings():  # generations no run reached are NaN, and stay out of the plot
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, std = np.nanmean(v, axis=0), np.nanstd(v, axis=0)
        gens = np.arange(1, v.shape[1] + 1)
        (line,) = ax.plot(gens, mean, label=f"{label} (mean ± std, {v.shape[0]} runs)")
        ax.fill_between(gens, mean - std, mean + std, color=line.get_color(), alpha=0.2, lw=0)
    if max_fitness is not None:
        ax.axhline(max_fitness, color="grey", lw=0.8, ls="--", label=f"success ({max_fitness:g} steps)")
    ax.set_xlabel("generation")
    ax.set_ylabel("best fitness (control steps balanced)")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(title or "Best fitness per generation")
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    return fig


def _layout(graph: nx.DiGraph) -> dict:
    """Inputs and bias on the left, outputs on the right, hidden nodes in between by depth."""
    kinds = nx.get_node_attributes(graph, "kind")
    sources = [n for n, k in kinds.items() if k in ("input", "bias")]
    depth = {n: 0 for n in sources}
    frontier = list(sources)
    while frontier:  # breadth-first depth from the inputs; recurrent edges do not deepen
        nxt = []
        for n in frontier:
            for m in graph.successors(n):
                if m not in depth:
                    depth[m] = depth[n] + 1
                    nxt.append(m)
        frontier = nxt
    hidden_depth = max([d for n, d in depth.items() if kinds[n] == "hidden"], default=0)
    columns: dict[int, list] = {}
    for n, k in kinds.items():
        col = 0 if k in ("input", "bias") else hidden_depth + 1 if k == "output" else depth.get(n, 1)
        columns.setdefault(col, []).append(n)
    pos = {}
    for col, nodes in columns.items():
        for i, n in enumerate(sorted(nodes)):
            pos[n] = (col, (len(nodes) - 1) / 2 - i)
    return pos


def plot_topology(genomes: Genomes, config: NEATConfig, run: int = 0, index: int = 0, *,
                  labels: dict[int, str] | None = None, title: str = "") -> Figure:
    """A genome's network: edge width by |weight|, red excitatory / blue inhibitory,
    dashed when disabled; self-connections drawn as loops."""
    graph = to_networkx(genomes, config, run, index)
    pos = _layout(graph)
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.subplots()
    kinds = nx.get_node_attributes(graph, "kind")
    colours = {"input": "#9ecae1", "bias": "#d9d9d9", "output": "#fdae6b", "hidden": "#a1d99b"}
    nx.draw_networkx_nodes(graph, pos, ax=ax, node_color=[colours[kinds[n]] for n in graph.nodes],
                           node_size=600, edgecolors="black")
    names = {n: (labels or {}).get(n, f"{kinds[n][0]}{n}") for n in graph.nodes}
    nx.draw_networkx_labels(graph, pos, labels=names, ax=ax, font_size=8)
    weights = [abs(d["weight"]) for _, _, d in graph.edges(data=True)]
    w_max = max(weights, default=1.0) or 1.0
    for (u, v, d), w in zip(graph.edges(data=True), weights, strict=True):
        nx.draw_networkx_edges(
            graph, pos, edgelist=[(u, v)], ax=ax, width=0.5 + 3.5 * w / w_max,
            edge_color="tab:red" if d["weight"] >= 0 else "tab:blue", style="solid" if d["enabled"] else "dashed",
            arrows=True, arrowsize=12, node_size=600, connectionstyle="arc3,rad=0.15")
    ax.set_title(title or f"run {run}, genome {index}: {graph.number_of_nodes()} nodes, "
                 f"{graph.number_of_edges()} connections, sigma {graph.graph['sigma']:.3g}")
    ax.legend(handles=[Line2D([], [], color="tab:red", lw=2, label="excitatory (w > 0)"),
                       Line2D([], [], color="tab:blue", lw=2, label="inhibitory (w < 0)"),
                       Line2D([], [], color="grey", lw=1.5, ls="--", label="disabled"),
                       Line2D([], [], color="grey", lw=0.5, label=f"width ∝ |w| (max {w_max:.3g})")],
              loc="lower center", bbox_to_anchor=(0.5, -0.02), ncols=4, fontsize=7, frameon=False)
    ax.margins(0.15)
    ax.set_axis_off()
    return fig


def _draw_species(ax, sizes: np.ndarray) -> None:
    gens = np.arange(1, sizes.shape[0] + 1)
    if sizes.shape[1]:
        # tab20's dark shades first, then its light ones: neighbouring bands never share a hue
        # until more than 20 species have lived.
        colours = [colormaps["tab20"]((2 * k) % 20 + (k // 10) % 2) for k in range(sizes.shape[1])]
        ax.stackplot(gens, sizes.T, colors=colours, alpha=0.9, lw=0.3, edgecolor="white")
    ax.set_xlabel("generation")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("genomes per species")
    ax.set_xlim(gens[0], max(gens[-1], gens[0] + 1) if len(gens) else 2)
    ax.set_ylim(0, sizes.sum(1).max() if sizes.size else 1)


def plot_species_sizes(sizes: Tensor | np.ndarray, *, title: str = "") -> Figure:
    """Species sizes per generation as a stacked area: ``sizes[generation, species]`` genomes
    (0 before a species appears and after it dies); one colour per species."""
    s = _numpy(sizes)
    if s.ndim != 2:
        raise ValueError(f"sizes must be [generations, species], got shape {s.shape}")
    fig = Figure(figsize=(7, 3.5), layout="constrained")
    ax = fig.subplots()
    _draw_species(ax, s)
    ax.set_title(title or f"species sizes ({s.shape[1]} species so far)")
    return fig


def plot_evolution_progress(best: Tensor | np.ndarray, mean: Tensor | np.ndarray, sizes: Tensor | np.ndarray, *,
                            max_fitness: float | None = None, title: str = "",
                            fitness_label: str = "control steps balanced", unit: str = "steps") -> Figure:
    """One run's progress: best and mean fitness per generation above species sizes as a
    stacked area (``sizes[generation, species]``). Redraw it each generation for a live plot.
    ``fitness_label``/``unit`` name the fitness (a return may be negative: the axis then
    follows the data instead of starting at 0)."""
    b, m, s = _numpy(best), _numpy(mean), _numpy(sizes)
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    ax_f, ax_s = fig.subplots(2, 1, sharex=True, height_ratios=[3, 2])
    gens = np.arange(1, len(b) + 1)
    ax_f.plot(gens, b, marker=".", color="tab:red", label="best")
    ax_f.plot(gens, m, marker=".", color="tab:blue", label="mean")
    if max_fitness is not None:
        ax_f.axhline(max_fitness, color="grey", lw=0.8, ls="--", label=f"target ({max_fitness:g} {unit})".replace(" )", ")"))
    ax_f.set_ylabel(f"fitness ({fitness_label})")
    if len(m) and float(np.min(m)) >= 0:
        ax_f.set_ylim(bottom=0)
    ax_f.grid(alpha=0.3)
    ax_f.legend(loc="upper left")
    if not title and len(b):
        title = f"generation {len(b)}: best {b[-1]:g}, mean {m[-1]:.4g}"
    ax_f.set_title(title)
    _draw_species(ax_s, s)
    ax_s.set_title(f"species sizes ({s.shape[1]} species so far)", fontsize="medium")
    return fig


def plot_search_progress(log, *, max_fitness: float | None = None, title: str = "") -> Figure:
    """An EvoTorch search's fitness per generation, from its ``PandasLogger``'s
    ``to_dataframe()`` (or any mapping of equal-length columns): ``mean_eval`` (the population's
    mean), ``pop_best_eval`` (the generation's best) and ``best_eval`` (the best so far) if
    present, plus ``median_eval``; fitness in control steps balanced. The generation numbers
    are the frame's index (EvoTorch's ``iter``) when it has one, else 1, 2, ..."""
    columns = {"best_eval": ("best so far", "tab:red", "-"), "pop_best_eval": ("best of generation", "tab:orange", ":"),
               "median_eval": ("median of population", "tab:green", "--"),
               "mean_eval": ("mean of population", "tab:blue", "-")}
    present = [c for c in columns if c in log]
    if "mean_eval" not in present:
        raise ValueError(f"log must have a 'mean_eval' column (an EvoTorch PandasLogger frame), got {list(log)}")
    mean = _numpy(log["mean_eval"])
    index = getattr(log, "index", None)
    gens = _numpy(index) if index is not None and len(index) == len(mean) else np.arange(1, len(mean) + 1)
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.subplots()
    for c in present:
        label, colour, style = columns[c]
        ax.plot(gens, _numpy(log[c]), color=colour, ls=style, lw=1.6 if c in ("best_eval", "mean_eval") else 1.1,
                label=label)
    if max_fitness is not None:
        ax.axhline(max_fitness, color="grey", lw=0.8, ls="--", label=f"cap ({max_fitness:g} steps)")
    ax.set_xlabel("generation")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("fitness (control steps balanced)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    ax.set_title(title or f"weight search: {len(mean)} generations")
    return fig


class EvolutionHistory(BaseReporter):
    """A NEAT reporter recording one run's best and mean fitness and its species sizes each
    generation, for ``plot_evolution_progress`` (species keep their run-wide number, so a
    species is one band of the stacked area however its slot is reused)."""

    def __init__(self, run: int = 0) -> None:
        self.run = run
        self.best: list[float] = []
        self.mean: list[float] = []
        self._sizes: list[dict[int, int]] = []

    def end_generation(self, status: GenerationStatus) -> None:
        st = status.run_statistics
        self.best.append(st["best"][self.run].item())
        self.mean.append(st["mean"][self.run].item())
        slots = status.species[self.run].cpu()
        ident = status.species_ident[self.run].cpu()
        counts = slots.bincount(minlength=ident.numel())
        self._sizes.append({int(ident[k]): int(c) for k, c in enumerate(counts.tolist()) if c > 0})

    def species_sizes(self) -> np.ndarray:
        """``[generations, species]`` genome counts, species in order of their number."""
        ids = sorted({k for row in self._sizes for k in row})
        col = {k: j for j, k in enumerate(ids)}
        out = np.zeros((len(self._sizes), len(ids)))
        for g, row in enumerate(self._sizes):
            for k, c in row.items():
                out[g, col[k]] = c
        return out

    def plot(self, *, max_fitness: float | None = None, title: str = "",
             fitness_label: str = "control steps balanced", unit: str = "steps") -> Figure:
        return plot_evolution_progress(self.best, self.mean, self.species_sizes(), max_fitness=max_fitness,
                                       title=title, fitness_label=fitness_label, unit=unit)

