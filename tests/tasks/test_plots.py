"""Plots run headless and draw something (images with labelled axes, non-blank pixels)."""

import math

import numpy as np
import torch
from matplotlib.image import imread

from evolution import NEAT
from snn_torch.plots import save_figure
from tasks.cartpole import DEFAULT_PLANT
from tasks.controllers import SpikingPolicy, SpikingSpec, closed_loop
from tasks.experiments.cartpole import controller_config, nonmarkov_start
from tasks.plots import plot_fitness_progress, plot_raster, plot_topology, plot_trajectory


def _non_blank(path):
    img = imread(path)
    assert img.shape[0] > 200 and img.shape[1] > 300
    assert np.std(img[..., :3]) > 0.05


def test_all_cartpole_plots_write_images(tmp_path):
    cfg = controller_config("snn", pop_size=10, node_add_prob=0.6, conn_add_prob=0.6)
    neat = NEAT(cfg, seeds=[0])
    neat.run(lambda g: g.num_genes().double(), 4)
    g = neat.genomes
    best = {"NEAT-SNN": torch.rand(20, 5) * 5000, "NEAT": torch.rand(20, 5) * 3000}
    fig = plot_fitness_progress(best, max_fitness=5000)
    assert fig.axes[0].get_xlabel() == "generation" and "fitness" in fig.axes[0].get_ylabel()
    _non_blank(save_figure(fig, tmp_path / "fig8.png"))

    one = g.gather(torch.tensor([[0]]))
    steps, trace = closed_loop(SpikingPolicy(one, cfg, SpikingSpec(), 0.01, DEFAULT_PLANT),
                               nonmarkov_start(1), tau_s=0.01, max_steps=100, record=True)
    fig = plot_trajectory(trace["x"][:, 0], trace["theta"][:, 0], trace["force"][:, 0], tau_s=0.01)
    assert [a.get_ylabel() for a in fig.axes] == ["cart position x (m)", "pole angle θ (deg)", "force F (N)"]
    _non_blank(save_figure(fig, tmp_path / "trajectory.png"))
    assert math.isclose(fig.axes[2].get_xlim()[1], len(trace["x"]) * 0.01, rel_tol=0.2)

    _non_blank(save_figure(plot_topology(g, cfg, 0, 0, labels={0: "x", 1: "θ", 2: "F"}), tmp_path / "topology.png"))
    _non_blank(save_figure(plot_raster(trace["activity"][:, 0], tau_s=0.01), tmp_path / "raster.png"))
