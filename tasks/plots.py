"""Figures for the cart-pole experiments and the notebooks: fitness progress (the paper's
Fig. 8), trajectories (Figs. 3, 4, 6, 7), a champion's topology (Fig. 5), spike rasters,
species sizes, a cart-pole animation, a training-loss curve, and an EvoTorch weight search's
progress with the success rates it reaches.

Every function returns a ``matplotlib.figure.Figure`` (``animate_cartpole`` a
``FuncAnimation``) built without pyplot, so it works headless (Agg) and inline in notebooks;
``snn_torch.plots.save_figure`` writes a figure atomically. ``EvolutionHistory`` is a NEAT
reporter that records what the progress plots draw, one generation at a time.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import networkx as nx
import numpy as np
from matplotlib import colormaps
from matplotlib.animation import FuncAnimation
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator
from torch import Tensor

from evolution.config import NEATConfig
from evolution.genome_io import to_networkx
from evolution.population import Genomes
from evolution.reporters import BaseReporter
from tasks.cartpole import DEFAULT_PLANT, CartPoleParams

if TYPE_CHECKING:
    from evolution.neat import NEAT

__all__ = ["plot_best_fitness_mean_std", "plot_trajectory", "plot_topology", "plot_raster",
           "plot_episode", "plot_species_sizes", "plot_evolution_progress", "plot_training_curve",
           "plot_search_progress", "plot_success_rates", "animate_cartpole", "EvolutionHistory"]


def _numpy(values) -> np.ndarray:
    """A float64 numpy array from a tensor, array or list."""
    if isinstance(values, Tensor):
        return values.detach().double().cpu().numpy()
    return np.asarray(values, dtype=np.float64)


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


def plot_trajectory(x_m: Tensor, theta_rad: Tensor | dict[str, Tensor], force_n: Tensor | None, *, tau_s: float,
                    title: str = "") -> Figure:
    """Cart position (m), pole angle (deg) and, if given, force (N) against time (s).
    ``theta_rad``: one pole's angle, or ``{label: angle}`` for several poles (one axis, a legend)."""
    rows = 3 if force_n is not None else 2
    fig = Figure(figsize=(7, 1.9 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True)
    t = np.arange(1, len(x_m) + 1) * tau_s
    axes[0].plot(t, x_m.cpu().numpy(), color="tab:blue", lw=0.8)
    axes[0].set_ylabel("cart position x (m)")
    if isinstance(theta_rad, dict):
        for i, (label, angle) in enumerate(theta_rad.items()):
            axes[1].plot(t, np.degrees(angle.cpu().numpy()), color=f"C{i + 1}", lw=0.8, label=label)
        axes[1].legend(fontsize=8)
        axes[1].set_ylabel("pole angles (deg)")
    else:
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
    ax.legend(handles=[Line2D([], [], color="tab:red", lw=2, label="excitatory (w > 0)"),
                       Line2D([], [], color="tab:blue", lw=2, label="inhibitory (w < 0)"),
                       Line2D([], [], color="grey", lw=1.5, ls="--", label="disabled"),
                       Line2D([], [], color="grey", lw=0.5, label=f"width ∝ |w| (max {w_max:.3g})")],
              loc="lower center", bbox_to_anchor=(0.5, -0.02), ncols=4, fontsize=7, frameon=False)
    ax.margins(0.15)
    ax.set_axis_off()
    return fig


def _draw_raster(ax, a: np.ndarray, t: np.ndarray, names: list[str] | None) -> None:
    """One row per neuron, a tick per bin with spikes; the tick thickens with the count (up to 4)."""
    for n in range(a.shape[1]):
        hit = a[:, n] > 0
        ax.vlines(t[hit], n - 0.4, n + 0.4, color="black", linewidths=0.8 + 0.6 * (np.minimum(a[hit, n], 4) - 1))
    labels = names or [str(n) for n in range(a.shape[1])]
    step = max(1, a.shape[1] // 16)  # at most ~16 tick labels, so they stay readable
    ax.set_yticks(range(0, a.shape[1], step), labels[::step])
    ax.set_ylim(-0.7, a.shape[1] - 0.3)
    ax.invert_yaxis()
    ax.set_ylabel("neuron")


def plot_raster(activity: Tensor, *, tau_s: float, names: list[str] | None = None, title: str = "",
                time_unit: str = "s") -> Figure:
    """Spike counts per time bin ``[T, N]`` (a control step of ``tau_s`` seconds) as a raster,
    one row per neuron; ``time_unit`` ``"s"`` or ``"ms"`` for the time axis."""
    if time_unit not in ("s", "ms"):
        raise ValueError(f"time_unit must be 's' or 'ms', got {time_unit!r}")
    a = _numpy(activity)
    fig = Figure(figsize=(7, min(0.3 * a.shape[1], 4.5) + 1.2), layout="constrained")
    ax = fig.subplots()
    t = np.arange(1, a.shape[0] + 1) * tau_s * (1000.0 if time_unit == "ms" else 1.0)
    _draw_raster(ax, a, t, names)
    ax.set_xlim(0, t[-1] if len(t) else 1)
    ax.set_xlabel(f"time ({time_unit})")
    ax.set_title(title or "spikes per time bin")
    return fig


def plot_episode(activity: Tensor, x_m: Tensor, theta_rad: Tensor, force_n: Tensor, *, tau_s: float,
                 names: list[str] | None = None, title: str = "") -> Figure:
    """A controller's episode: spike raster ``[T, N]`` above cart position (m), pole angle
    (deg) and force (N), all against time (s) on one shared axis."""
    a = _numpy(activity)
    raster_h = min(0.3 * a.shape[1], 4.0) + 0.6
    fig = Figure(figsize=(8, raster_h + 4.8), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True, height_ratios=[raster_h, 1.4, 1.4, 1.4])
    t = np.arange(1, a.shape[0] + 1) * tau_s
    # Neurons fire several times per control step, so ticks would merge into bars: show the
    # spike count of each neuron in each step as a shade instead.
    im = axes[0].imshow(a.T, aspect="auto", interpolation="nearest", cmap="Greys", vmin=0,
                        vmax=max(float(a.max()) if a.size else 1.0, 1.0),
                        extent=(0.0, len(t) * tau_s, a.shape[1] - 0.5, -0.5))
    labels = names or [str(n) for n in range(a.shape[1])]
    step = max(1, a.shape[1] // 16)
    axes[0].set_yticks(range(0, a.shape[1], step), labels[::step])
    axes[0].set_ylabel("neuron")
    fig.colorbar(im, ax=axes[0], location="top", shrink=0.35, aspect=25, pad=0.02,
                 label=f"spikes per control step ({tau_s * 1000:g} ms)")
    fig.suptitle(title or "one episode: spikes and the cart-pole")
    axes[1].plot(t, _numpy(x_m), color="tab:blue", lw=0.8)
    axes[1].set_ylabel("x (m)")
    axes[2].plot(t, np.degrees(_numpy(theta_rad)), color="tab:orange", lw=0.8)
    axes[2].set_ylabel("θ (deg)")
    axes[3].plot(t, _numpy(force_n), color="tab:green", lw=0.5)
    axes[3].set_ylabel("F (N)")
    axes[3].set_xlabel("time (s)")
    axes[3].set_xlim(0, t[-1] if len(t) else 1)
    for ax in axes[1:]:
        ax.grid(alpha=0.3)
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


def plot_training_curve(losses, *, accuracy=None, title: str = "") -> Figure:
    """Loss per training step and, if given, accuracy (fraction correct) on a second axis."""
    loss = _numpy(losses)
    fig = Figure(figsize=(7, 3.8), layout="constrained")
    ax = fig.subplots()
    steps = np.arange(1, len(loss) + 1)
    handles = ax.plot(steps, loss, color="tab:blue", label="loss")
    ax.set_xlabel("training step")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("loss (cross-entropy, nats)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    if accuracy is not None:
        ax_acc = ax.twinx()
        handles += ax_acc.plot(steps, _numpy(accuracy), color="tab:orange", label="accuracy")
        ax_acc.set_ylabel("accuracy (fraction correct)")
        ax_acc.set_ylim(0, 1.02)
    ax.legend(handles=handles, loc="center right")
    ax.set_title(title or "training")
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


def plot_success_rates(rates: dict[str, float], *, num_starts: int | None = None, title: str = "") -> Figure:
    """Bars of success rates (fractions in [0, 1], shown in percent), e.g. one controller before
    and after tuning; each bar is labelled with its value (and count of ``num_starts``)."""
    if not rates:
        raise ValueError("rates is empty")
    names, values = list(rates), [float(v) for v in rates.values()]
    if not all(0.0 <= v <= 1.0 for v in values):
        raise ValueError(f"rates must be fractions in [0, 1], got {values}")
    fig = Figure(figsize=(max(3.5, 1.6 * len(names) + 1.5), 3.8), layout="constrained")
    ax = fig.subplots()
    colours = [colormaps["tab10"](k % 10) for k in range(len(names))]
    bars = ax.bar(names, [100.0 * v for v in values], color=colours, width=0.6)
    texts = [f"{100.0 * v:.1f} %" + (f"\n({round(v * num_starts)} of {num_starts})" if num_starts else "")
             for v in values]
    ax.bar_label(bars, texts, padding=2, fontsize=9)
    ax.set_ylim(0, 115)
    ax.set_yticks(range(0, 101, 20))
    what = f"of the {num_starts} start states" if num_starts else "of the start states"
    ax.set_ylabel(f"success rate (% {what})")
    ax.grid(axis="y", alpha=0.3)
    ax.set_title(title or "success rate")
    return fig


def animate_cartpole(x_m: Tensor | np.ndarray, theta_rad: Tensor | np.ndarray, tau_s: float, *,
                     force_n: Tensor | np.ndarray | None = None, plant: CartPoleParams = DEFAULT_PLANT,
                     every: int = 1, title: str = "", dpi: int = 72) -> FuncAnimation:
    """The cart-pole moving: one frame per ``every`` control steps, played in real time.

    ``x_m[T]``, ``theta_rad[T]`` (and ``force_n[T]``, drawn as an arrow) are the state after
    each control step of ``tau_s`` seconds. In a notebook show it with
    ``IPython.display.HTML(anim.to_jshtml())`` (no ffmpeg needed).
    """
    x, th = _numpy(x_m), _numpy(theta_rad)
    f = None if force_n is None else _numpy(force_n)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    frames = list(range(0, len(x), every)) or [0]
    pole = 2.0 * plant.half_length
    fig = Figure(figsize=(7, 2.8), dpi=dpi, layout="constrained")
    ax = fig.subplots()
    lim = plant.x_limit
    ax.set_xlim(-lim - 0.3, lim + 0.3)
    cart_w, cart_h = 0.4, 0.2
    ax.set_ylim(-0.25, cart_h + pole + 0.25)
    ax.set_aspect("equal")
    ax.axhline(0.0, color="black", lw=1.0)
    for edge in (-lim, lim):
        ax.axvline(edge, color="tab:red", lw=1.0, ls="--")
    ax.set_xlabel("cart position x (m)")
    ax.set_yticks([])
    cart = Rectangle((0, 0), cart_w, cart_h, facecolor="tab:blue", edgecolor="black")
    ax.add_patch(cart)
    (rod,) = ax.plot([], [], color="tab:orange", lw=4, solid_capstyle="round")
    (push,) = ax.plot([], [], color="tab:green", lw=3, zorder=3, marker=">", markevery=[1], markersize=6)
    label = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize=9,
                    bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})
    ax.set_title(title or "cart-pole")

    def draw(i: int):
        cx, a = x[i], th[i]
        cart.set_xy((cx - cart_w / 2, 0.0))
        top = (cx + pole * np.sin(a), cart_h + pole * np.cos(a))
        rod.set_data([cx, top[0]], [cart_h, top[1]])
        text = f"t = {(i + 1) * tau_s:5.2f} s   x = {cx:+.2f} m   θ = {np.degrees(a):+.1f}°"
        if f is not None:
            push.set_data([cx, cx + 0.06 * f[i]], [cart_h / 2, cart_h / 2])
            push.set_marker(">" if f[i] >= 0 else "<")
            text += f"   F = {f[i]:+.1f} N"
        label.set_text(text)
        return cart, rod, push, label

    return FuncAnimation(fig, draw, frames=frames, interval=1000.0 * tau_s * every, blit=False)


class EvolutionHistory(BaseReporter):
    """A NEAT reporter recording one run's best and mean fitness and its species sizes each
    generation, for ``plot_evolution_progress`` (species keep their run-wide number, so a
    species is one band of the stacked area however its slot is reused)."""

    def __init__(self, run: int = 0) -> None:
        self.run = run
        self.best: list[float] = []
        self.mean: list[float] = []
        self._sizes: list[dict[int, int]] = []

    def post_evaluate(self, neat: NEAT, fitness: Tensor) -> None:
        f = fitness[self.run].double().cpu()
        self.best.append(f.max().item())
        self.mean.append(f.mean().item())
        slots = neat.species[self.run].cpu()
        ident = neat.species_state.ident[self.run].cpu()
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
