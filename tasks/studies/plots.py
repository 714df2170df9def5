"""Figures of the cart-pole studies: trajectories (Qiu et al.'s Figs. 3, 4, 6, 7), an episode with
the spikes behind it, generalisation success rates, and a cart-pole animation.

Every function returns a ``matplotlib.figure.Figure`` (``animate_cartpole`` a ``FuncAnimation``)
built without pyplot, so it works headless (Agg) and inline in notebooks. NEAT's own figures
(fitness progress, topology, species) are in ``evolution.plots``; spike rasters in ``snn_torch.plots``.
"""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps
from matplotlib.animation import FuncAnimation
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from torch import Tensor

from snn_torch.plots import as_numpy as _numpy
from tasks.cartpole import DEFAULT_PLANT, CartPoleParams

__all__ = ["plot_trajectory", "plot_episode", "plot_success_rates", "animate_cartpole"]


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

