"""Spiking figures: a neuron's voltage response (Qiu et al. Fig. 1), its f-I curve (Fig. 2), spike
rasters of a network, and a training-loss curve for torch models with spiking layers.

Computation and drawing are separate: ``voltage_response`` and ``fi_curve`` return
tensors; ``plot_*`` draw them on a ``matplotlib.figure.Figure`` (no pyplot state, so they
work headless and inline in notebooks); ``save_neuron_figures`` writes both PNGs.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from torch import Tensor

from snn_torch._files import file_mode
from snn_torch.functional.izhikevich import (
    QIU2019,
    QIU2019_FIG1,
    IzhikevichParams,
    check_dt,
    izhikevich_init,
    izhikevich_run,
    izhikevich_step,
)

__all__ = [
    "square_wave",
    "voltage_response",
    "fi_curve",
    "plot_voltage_response",
    "plot_fi_curve",
    "save_figure",
    "save_neuron_figures",
    "plot_raster",
    "plot_training_curve",
    "as_numpy",
]


def square_wave(t_ms: float, dt_ms: float, *, amplitude: float = 10.0, period_ms: float = 200.0,
                delay_ms: float = 50.0) -> Tensor:
    """A square current (mV/ms, the paper's nA): 0 until ``delay_ms``, then on/off halves."""
    t = (torch.arange(int(round(t_ms / check_dt(dt_ms))), dtype=torch.float64) + 0.5) * dt_ms
    on = (t >= delay_ms) & (((t - delay_ms) % period_ms) < period_ms / 2)
    return on.to(torch.float64) * amplitude


def voltage_response(p: IzhikevichParams, current: Tensor, *, dt_ms: float) -> tuple[Tensor, Tensor, Tensor]:
    """Membrane potential of one neuron driven by ``current[T]``, in float64.

    Returns ``(t_ms [T], v_mv [T], spikes [T])``. At a spike the trace shows ``v_peak`` (the
    spike's top) rather than the post-reset value, as Izhikevich's own plots do.
    """
    dt_ms = check_dt(dt_ms)
    current = current.to(torch.float64)
    if current.dim() != 1 or not bool(torch.isfinite(current).all()):
        raise ValueError("current must be a 1-D tensor of finite values (mV/ms)")
    state = izhikevich_init((), p, dtype=torch.float64)
    v_trace, z_trace = [], []
    for i in current:
        z, state = izhikevich_step(i, state, p, dt_ms=dt_ms, validate=False)
        v_trace.append(torch.where(z > 0, torch.as_tensor(p.v_peak, dtype=torch.float64), state.v))
        z_trace.append(z)
    t = (torch.arange(len(current), dtype=torch.float64) + 1) * dt_ms
    return t, torch.stack(v_trace), torch.stack(z_trace)


def fi_curve(p: IzhikevichParams, currents: Tensor, *, dt_ms: float = 0.02, t_ms: float = 1000.0,
             transient_ms: float = 100.0) -> tuple[Tensor, Tensor]:
    """Steady-state firing rate (Hz) for each constant current (mV/ms), all in one batch.

    Rates are spike counts over ``[transient_ms, t_ms]`` divided by that window. The default
    0.02 ms step resolves rates of well over 1 kHz (the paper's curve reaches I = 200).
    """
    check_dt(dt_ms)
    if not 0 <= transient_ms < t_ms:
        raise ValueError(f"need 0 <= transient_ms < t_ms, got {transient_ms} and {t_ms}")
    currents = currents.to(torch.float64).flatten()
    steps = int(round(t_ms / dt_ms))
    skip = int(round(transient_ms / dt_ms))
    state = izhikevich_init(currents.shape, p, dtype=torch.float64)
    z, _ = izhikevich_run(currents.expand(steps, -1), state, p, dt_ms=dt_ms)
    rates = z[skip:].sum(0) * 1000.0 / ((steps - skip) * dt_ms)
    return currents, rates


def plot_voltage_response(t_ms: Tensor, v_mv: Tensor, current: Tensor, *, title: str = "") -> Figure:
    """Two stacked panels: membrane potential (mV) over input current (nA) against time (ms)."""
    fig = Figure(figsize=(7, 4.5), layout="constrained")
    ax_v, ax_i = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    ax_v.plot(t_ms, v_mv, lw=0.8, color="tab:blue")
    ax_v.set_ylabel("membrane potential v (mV)")
    ax_v.set_title(title)
    ax_i.plot(t_ms, current, lw=1.0, color="tab:red")
    ax_i.set_ylabel("current I (nA)")
    ax_i.set_xlabel("time (ms)")
    for ax in (ax_v, ax_i):
        ax.grid(alpha=0.3)
    return fig


def plot_fi_curve(currents: Tensor, rates_hz: Tensor, *, title: str = "") -> Figure:
    """Firing rate (Hz) against injected current (nA)."""
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(currents, rates_hz, marker=".", color="tab:blue")
    ax.set_xlabel("input current I (nA)")
    ax.set_ylabel("mean firing rate f (Hz)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike, *, dpi: int = 150) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically (temp file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".png", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fig.savefig(fh, format="png", dpi=dpi)
            os.fchmod(fh.fileno(), file_mode())  # as open() would have made it, not mkstemp's 0o600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def save_neuron_figures(out_dir: str | os.PathLike, *, dt_ms: float = 0.02) -> list[Path]:
    """Regenerate Qiu et al.'s Fig. 1 and Fig. 2 as PNGs in ``out_dir``; returns the paths."""
    out = Path(out_dir)
    current = square_wave(500.0, dt_ms)
    t, v, _ = voltage_response(QIU2019_FIG1, current, dt_ms=dt_ms)
    fig1 = plot_voltage_response(
        t, v, current, title="Fig. 1: Izhikevich neuron, a=0.02 b=0.2 c=-65 mV d=2, $v_t$=30 mV")
    currents, rates = fi_curve(QIU2019, torch.linspace(0.0, 200.0, 201), dt_ms=dt_ms, t_ms=600.0)
    fig2 = plot_fi_curve(currents, rates, title="Fig. 2: f-I curve, a=0.02 b=0.2 c=-50 mV d=2, $v_t$=30 mV")
    return [save_figure(fig1, out / "fig1_voltage_response.png"),
            save_figure(fig2, out / "fig2_fi_curve.png")]


def as_numpy(values) -> np.ndarray:
    """A float64 numpy array from a tensor, array or list."""
    if isinstance(values, Tensor):
        return values.detach().double().cpu().numpy()
    return np.asarray(values, dtype=np.float64)


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
    a = as_numpy(activity)
    fig = Figure(figsize=(7, min(0.3 * a.shape[1], 4.5) + 1.2), layout="constrained")
    ax = fig.subplots()
    t = np.arange(1, a.shape[0] + 1) * tau_s * (1000.0 if time_unit == "ms" else 1.0)
    _draw_raster(ax, a, t, names)
    ax.set_xlim(0, t[-1] if len(t) else 1)
    ax.set_xlabel(f"time ({time_unit})")
    ax.set_title(title or "spikes per time bin")
    return fig


def plot_training_curve(losses, *, accuracy=None, title: str = "") -> Figure:
    """Loss per training step and, if given, accuracy (fraction correct) on a second axis."""
    loss = as_numpy(losses)
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
        handles += ax_acc.plot(steps, as_numpy(accuracy), color="tab:orange", label="accuracy")
        ax_acc.set_ylabel("accuracy (fraction correct)")
        ax_acc.set_ylim(0, 1.02)
    ax.legend(handles=handles, loc="center right")
    ax.set_title(title or "training")
    return fig
