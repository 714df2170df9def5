"""Plots run headless and draw something (images with labelled axes, non-blank pixels)."""

import math
import re

import numpy as np
import pytest
import torch
from matplotlib.animation import PillowWriter
from matplotlib.image import imread
from matplotlib.patches import FancyArrowPatch
from PIL import Image

from evolution import NEAT, make_controller, rollout
from evolution.plots import (
    EvolutionHistory,
    plot_best_fitness_mean_std,
    plot_search_progress,
    plot_species_sizes,
    plot_topology,
)
from evolution.population import initial_genomes
from evolution.rng import RunRNG
from snn_torch.plots import plot_raster, plot_training_curve, save_figure
from tasks.cartpole import CartPoleTask
from tasks.studies.cartpole import controller_config
from tasks.studies.plots import animate_cartpole, plot_episode, plot_success_rates, plot_trajectory


def _non_blank(path):
    img = imread(path)
    assert img.shape[0] > 200 and img.shape[1] > 300
    assert np.std(img[..., :3]) > 0.05


def test_all_cartpole_plots_write_images(tmp_path):
    cfg = controller_config("snn", pop_size=10, node_add_prob=0.6, conn_add_prob=0.6)
    neat = NEAT(cfg, seeds=[0])
    neat.run(lambda g: g.num_genes().double(), 4)
    g = neat.genomes
    one = g.gather(torch.tensor([[0]]))
    task = CartPoleTask.nonmarkov(max_steps=100)  # tau 0.01 s, from theta = 3 degrees
    trace = rollout(task, make_controller(one, cfg, task), record=True).trace
    x, theta = trace["state"][:, 0, 0], trace["state"][:, 0, 2]
    force, activity = trace["action"][:, 0, 0], trace["activity"][:, 0]
    fig = plot_trajectory(x, theta, force, tau_s=0.01)
    assert [a.get_ylabel() for a in fig.axes] == ["cart position x (m)", "pole angle θ (deg)", "force F (N)"]
    _non_blank(save_figure(fig, tmp_path / "trajectory.png"))
    assert math.isclose(fig.axes[2].get_xlim()[1], len(x) * 0.01, rel_tol=0.2)

    _non_blank(save_figure(plot_topology(g, cfg, 0, 0, labels={0: "x", 1: "θ", 2: "F"}), tmp_path / "topology.png"))
    _non_blank(save_figure(plot_raster(activity, tau_s=0.01), tmp_path / "raster.png"))


def test_best_fitness_mean_std_plots_mean_and_band_per_controller(tmp_path):
    snn = np.array([[100.0, 300.0, 500.0], [300.0, 500.0, np.nan]])  # run 2 stopped after generation 2
    sigmoid = torch.tensor([[50.0, 60.0, 70.0], [50.0, 80.0, 90.0], [50.0, 100.0, 110.0]])
    fig = plot_best_fitness_mean_std({"NEAT-SNN": snn, "NEAT": sigmoid}, max_fitness=5000, title="Fig. 8")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "generation" and ax.get_ylabel() == "best fitness (control steps balanced)"
    assert ax.get_title() == "Fig. 8"
    means = [line for line in ax.get_lines() if line.get_linestyle() == "-"]
    assert len(means) == 2
    np.testing.assert_allclose(means[0].get_xdata(), [1, 2, 3])
    np.testing.assert_allclose(means[0].get_ydata(), [200.0, 400.0, 500.0])  # NaN left out of the mean
    np.testing.assert_allclose(means[1].get_ydata(), [50.0, 80.0, 90.0])
    assert len(ax.collections) == 2  # one +-std band per controller
    band = ax.collections[1].get_paths()[0].vertices
    assert math.isclose(band[:, 1].max(), 90.0 + np.std([70.0, 90.0, 110.0]), rel_tol=1e-9)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["NEAT-SNN (mean ± std, 2 runs)", "NEAT (mean ± std, 3 runs)", "success (5000 steps)"]
    _non_blank(save_figure(fig, tmp_path / "fig8_mean_std.png"))


def test_species_sizes_stack_to_the_population(tmp_path):
    sizes = np.array([[10, 0, 0], [6, 4, 0], [3, 4, 3], [0, 7, 3]])
    fig = plot_species_sizes(sizes)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "generation" and ax.get_ylabel() == "genomes per species"
    assert len(ax.collections) == 3  # one band per species
    top = ax.collections[-1].get_paths()[0].vertices[:, 1].max()
    assert top == 10
    _non_blank(save_figure(fig, tmp_path / "species.png"))


def test_evolution_history_records_each_generation(tmp_path):
    cfg = controller_config("snn", pop_size=12, node_add_prob=0.6, conn_add_prob=0.6, compatibility_threshold=1.0)
    neat = NEAT(cfg, seeds=[3])
    history = neat.add_reporter(EvolutionHistory())
    neat.run(lambda g: g.num_genes().double(), 5)
    sizes = history.species_sizes()
    assert len(history.best) == len(history.mean) == 5 == sizes.shape[0]
    assert (sizes.sum(1) == 12).all()  # every genome belongs to one species each generation
    assert all(b >= m for b, m in zip(history.best, history.mean, strict=True))
    fig = history.plot(max_fitness=20)
    ax_f, ax_s = fig.axes
    assert ax_f.get_ylabel() == "fitness (control steps balanced)" and ax_s.get_xlabel() == "generation"
    assert [line.get_label() for line in ax_f.get_lines()] == ["best", "mean", "target (20 steps)"]
    np.testing.assert_allclose(ax_f.get_lines()[0].get_ydata(), history.best)
    assert len(ax_s.collections) == sizes.shape[1]
    _non_blank(save_figure(fig, tmp_path / "progress.png"))


def test_episode_raster_and_trajectory_share_time(tmp_path):
    T, N = 300, 3
    activity = torch.zeros(T, N)
    activity[::7, 0] = 1
    activity[::3, 2] = 3
    t = torch.arange(T) * 0.01
    fig = plot_episode(activity, 0.1 * t, 0.02 * torch.sin(t), 5 * torch.cos(t), tau_s=0.01, names=["x", "θ", "h5"])
    raster, x_ax, th_ax, f_ax = fig.axes[:4]
    assert [a.get_ylabel() for a in (raster, x_ax, th_ax, f_ax)] == ["neuron", "x (m)", "θ (deg)", "F (N)"]
    assert f_ax.get_xlabel() == "time (s)"
    image = raster.get_images()[0].get_array()
    assert image.shape == (N, T) and image.max() == 3 and image[1].sum() == 0
    assert [tick.get_text() for tick in raster.get_yticklabels()] == ["x", "θ", "h5"]
    assert math.isclose(f_ax.get_xlim()[1], T * 0.01) and math.isclose(raster.get_xlim()[1], T * 0.01)
    assert "spikes per control step" in fig.axes[-1].get_xlabel() + fig.axes[-1].get_ylabel()  # the colorbar
    _non_blank(save_figure(fig, tmp_path / "episode.png"))


def test_raster_in_milliseconds_draws_one_tick_per_spike(tmp_path):
    spikes = torch.zeros(40, 4)
    spikes[[3, 10, 20], 1] = 1
    spikes[5, 3] = 1
    fig = plot_raster(spikes, tau_s=0.0005, time_unit="ms")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time (ms)" and math.isclose(ax.get_xlim()[1], 20.0)
    assert sum(len(c.get_segments()) for c in ax.collections) == 4
    _non_blank(save_figure(fig, tmp_path / "raster_ms.png"))


def test_training_curve_shows_loss_and_accuracy(tmp_path):
    fig = plot_training_curve([1.2, 0.9, 0.5], accuracy=[0.5, 0.7, 0.9])
    loss_ax, acc_ax = fig.axes
    assert loss_ax.get_xlabel() == "training step" and "loss" in loss_ax.get_ylabel()
    assert "accuracy" in acc_ax.get_ylabel()
    np.testing.assert_allclose(loss_ax.get_lines()[0].get_ydata(), [1.2, 0.9, 0.5])
    np.testing.assert_allclose(acc_ax.get_lines()[0].get_ydata(), [0.5, 0.7, 0.9])
    _non_blank(save_figure(fig, tmp_path / "loss.png"))


def test_cartpole_animation_frames_follow_the_state(tmp_path):
    T, every = 50, 10
    x = torch.linspace(-1.0, 1.0, T)
    theta = torch.linspace(0.0, 0.2, T)
    anim = animate_cartpole(x, theta, 0.01, force_n=torch.full((T,), -5.0), every=every)
    html = anim.to_jshtml()
    assert len(re.findall(r"frames\[\d+\] = ", html)) == T // every
    anim.save(tmp_path / "cartpole.gif", writer=PillowWriter(fps=10))
    with Image.open(tmp_path / "cartpole.gif") as gif:
        assert gif.n_frames == T // every
    ax = anim._fig.axes[0]  # after saving, the artists show the last frame (step 41)
    assert ax.get_xlabel() == "cart position x (m)"
    cart = ax.patches[0]
    assert math.isclose(cart.get_x() + cart.get_width() / 2, x[40].item(), abs_tol=1e-6)
    rod = ax.get_lines()[-2]
    (x0, x1), (y0, y1) = rod.get_data()
    assert math.isclose(math.atan2(x1 - x0, y1 - y0), theta[40].item(), abs_tol=1e-6)
    assert "F = -5.0 N" in ax.texts[0].get_text()


def test_topology_draws_self_and_recurrent_connections(tmp_path):
    cfg = controller_config("snn")
    g = initial_genomes(cfg, RunRNG([0]))
    one = g.gather(torch.tensor([[0]]))
    h, out = cfg.first_hidden, cfg.first_output
    one.node[0, 0, h] = True
    for i, j, w in [(0, h, 1.0), (h, out, -2.0), (h, h, 0.5), (out, h, -0.3)]:  # self-loop, output -> hidden
        one.conn[0, 0, i, j], one.enabled[0, 0, i, j], one.weight[0, 0, i, j] = True, True, w
    fig = plot_topology(one, cfg, labels={0: "x", 1: "θ", out: "F"})
    ax = fig.axes[0]
    arrows = [p for p in ax.patches if isinstance(p, FancyArrowPatch)]
    assert len(arrows) == int(one.conn.sum()) == 6
    widths = sorted(p.get_linewidth() for p in arrows)
    assert widths[-1] > 3 * widths[0]  # width by |weight|
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[:2] == ["excitatory (w > 0)", "inhibitory (w < 0)"]
    _non_blank(save_figure(fig, tmp_path / "topology_loops.png"))


def test_search_progress_plots_evotorch_log_columns(tmp_path):
    pd = pytest.importorskip("pandas")
    log = pd.DataFrame({"mean_eval": [100.0, 150.0, 220.0], "median_eval": [90.0, 140.0, 230.0],
                        "pop_best_eval": [300.0, 280.0, 410.0], "best_eval": [300.0, 300.0, 410.0],
                        "worst_eval": [10.0, 10.0, 10.0]}, index=pd.Index([1, 2, 3], name="iter"))
    fig = plot_search_progress(log, max_fitness=1000, title="SNES")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "generation" and "control steps balanced" in ax.get_ylabel()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["best so far", "best of generation", "median of population", "mean of population",
                      "cap (1000 steps)"]
    assert list(ax.lines[3].get_ydata()) == [100.0, 150.0, 220.0]  # the mean
    _non_blank(save_figure(fig, tmp_path / "search.png"))
    # A plain mapping works too (generations numbered from 1); mean_eval is required.
    fig = plot_search_progress({"mean_eval": [1.0, 2.0]})
    assert list(fig.axes[0].lines[0].get_xdata()) == [1, 2]
    with pytest.raises(ValueError, match="mean_eval"):
        plot_search_progress({"best_eval": [1.0]})


def test_success_rates_bars_in_percent(tmp_path):
    fig = plot_success_rates({"champion": 0.3072, "tuned": torch.tensor(0.536).item()}, num_starts=625)
    ax = fig.axes[0]
    assert [round(p.get_height(), 2) for p in ax.patches] == [30.72, 53.6]
    assert "625 start states" in ax.get_ylabel()
    texts = [t.get_text() for t in ax.texts]
    assert texts == ["30.7 %\n(192 of 625)", "53.6 %\n(335 of 625)"]
    _non_blank(save_figure(fig, tmp_path / "rates.png"))
    with pytest.raises(ValueError):
        plot_success_rates({"bad": 1.5})
