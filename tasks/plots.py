"""Figures for the cart-pole experiments: fitness progress (the paper's Fig. 8), trajectories
(Figs. 3, 4, 6, 7), a champion's topology (Fig. 5) and a spike raster.

Every function returns a ``matplotlib.figure.Figure`` built without pyplot, so it works
headless (Agg) and inline in notebooks; ``snn_torch.plots.save_figure`` writes it atomically.
"""

from __future__ import annotations

import networkx as nx
import numpy as np
from matplotlib.figure import Figure
from torch import Tensor

from evolution.config import NEATConfig
from evolution.genome_io import to_networkx
from evolution.population import Genomes

__all__ = ["plot_fitness_progress", "plot_trajectory", "plot_topology", "plot_raster"]


def plot_fitness_progress(best: dict[str, Tensor], *, max_fitness: float | None = None,
                          title: str = "Best fitness per generation") -> Figure:
    """Mean and standard deviation over runs of the best fitness per generation.

    ``best[label]`` is ``[generations, runs]`` (NaN after a run stopped: a solved run keeps
    its final value, the usual convention for such plots, so pass it filled forward).
    """
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.subplots()
    for label, values in best.items():
        v = values.double().cpu().numpy()
        mean, std = np.nanmean(v, axis=1), np.nanstd(v, axis=1)
        gens = np.arange(1, len(mean) + 1)
        ax.plot(gens, mean, label=f"{label} (mean of {v.shape[1]} runs)")
        ax.fill_between(gens, mean - std, mean + std, alpha=0.2)
    if max_fitness is not None:
        ax.axhline(max_fitness, color="grey", lw=0.8, ls="--", label="success")
    ax.set_xlabel("generation")
    ax.set_ylabel("best fitness (time steps balanced)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    return fig


def plot_trajectory(x_m: Tensor, theta_rad: Tensor, force_n: Tensor | None, *, tau_s: float,
                    title: str = "") -> Figure:
    """Cart position (m), pole angle (deg) and, if given, force (N) against time (s)."""
    rows = 3 if force_n is not None else 2
    fig = Figure(figsize=(7, 1.9 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True)
    t = np.arange(1, len(x_m) + 1) * tau_s
    axes[0].plot(t, x_m.cpu().numpy(), color="tab:blue", lw=0.8)
    axes[0].set_ylabel("cart position x (m)")
    axes[1].plot(t, np.degrees(theta_rad.cpu().numpy()), color="tab:orange", lw=0.8)
    axes[1].set_ylabel("pole angle θ (deg)")
    if force_n is not None:
        axes[2].plot(t, force_n.cpu().numpy(), color="tab:green", lw=0.6)
        axes[2].set_ylabel("force F (N)")
    axes[-1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].set_title(title)
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
    ax.set_axis_off()
    return fig


def plot_raster(activity: Tensor, *, tau_s: float, names: list[str] | None = None, title: str = "") -> Figure:
    """Spike counts per control step ``[T, N]`` as a raster (one row per neuron)."""
    a = activity.detach().cpu().numpy()
    fig = Figure(figsize=(7, 0.35 * a.shape[1] + 1.2), layout="constrained")
    ax = fig.subplots()
    t = np.arange(1, a.shape[0] + 1) * tau_s
    for n in range(a.shape[1]):
        hit = a[:, n] > 0
        ax.scatter(t[hit], np.full(hit.sum(), n), s=2 + 4 * np.minimum(a[hit, n], 4), marker="|", color="black")
    ax.set_yticks(range(a.shape[1]), names or [str(n) for n in range(a.shape[1])])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("neuron")
    ax.set_title(title or "spikes per control step")
    return fig
