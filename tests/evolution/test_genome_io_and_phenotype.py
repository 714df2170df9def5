import json
import math

import networkx as nx
import pytest
import torch

from evolution.checkpoint import CheckpointError
from evolution.genome_io import genome_to_dict, load_genome, save_genome, to_networkx
from evolution.mutate import mutate_add_connection, mutate_add_node
from evolution.phenotype import SigmoidController, SigmoidSpec, SpikingController, SpikingSpec
from evolution.population import Genomes
from snn_torch import PopulationRecurrentIzhikevich
from snn_torch.functional import QIU2019, masked_weights, recurrent_init, recurrent_izhikevich_run
from snn_torch.modules.recurrent import PopulationRecurrentSigmoid
from tests.evolution.helpers import population, small_config


def _grown(cfg, seeds=(0, 1), rounds=3):
    g, rng = population(cfg, seeds)
    everyone = torch.ones(len(seeds), cfg.pop_size, dtype=torch.bool)
    for _ in range(rounds):
        g, _ = mutate_add_node(g, cfg, rng, everyone)
        g = mutate_add_connection(g, cfg, rng, everyone)
    return g


def test_genome_round_trip_and_networkx(tmp_path):
    cfg = small_config(node_add_prob=0.8, conn_add_prob=0.8)
    g = _grown(cfg)
    g.enabled[1, 2, 0, cfg.first_output] = False
    path = save_genome(tmp_path / "champ.json", g, cfg, run=1, index=2, fitness=3.5)
    back = load_genome(path, cfg)
    for name, t in back.tensors().items():
        assert torch.equal(t[0, 0], getattr(g, name)[1, 2]), name
    assert json.loads(path.read_text())["fitness"] == 3.5
    graph = to_networkx(g, cfg, run=1, index=2)
    assert isinstance(graph, nx.DiGraph)
    assert graph.number_of_edges() == int(g.conn[1, 2].sum())
    assert graph.nodes[0]["kind"] == "input" and graph.nodes[cfg.first_output]["kind"] == "output"
    assert graph.edges[0, cfg.first_output]["enabled"] is False


@pytest.mark.parametrize("mutilate, match", [
    (lambda d: d.update(format="other"), "not an snn-neat-genome"),
    (lambda d: d.update(version=99), "version 99"),
    (lambda d: d["connections"].append({"from": 0, "to": 99, "weight": 1.0, "enabled": True}), "'to' is 99"),
    (lambda d: d["connections"][0].update(weight=float("nan")), "finite number"),
    (lambda d: d["connections"].append(dict(d["connections"][0])), "appears twice"),
    (lambda d: d["connections"].append({"from": 3, "to": 0, "weight": 1.0, "enabled": True}), "into an input"),
    (lambda d: d["layout"].update(num_inputs=5), "layout"),
    (lambda d: d.update(sigma="x"), "sigma"),
])
def test_malformed_genome_files_name_file_and_fault(tmp_path, mutilate, match):
    cfg = small_config()
    g, _ = population(cfg)
    d = genome_to_dict(g, cfg)
    mutilate(d)
    path = tmp_path / "g.json"
    path.write_text(json.dumps(d))
    with pytest.raises(CheckpointError, match=match) as exc:
        load_genome(path, cfg)
    assert "g.json" in str(exc.value)


def test_a_genome_file_keeps_its_bias_value(tmp_path):
    """A genome evolved with NEAT 1.2.1's bias input (``bias_value`` 0.5) loads only where the bias is
    the same: elsewhere the network would act differently."""
    import dataclasses

    cfg = small_config()
    g, _ = population(cfg)
    half = dataclasses.replace(cfg, bias_value=0.5)
    assert "bias_value" not in genome_to_dict(g, cfg)["layout"]  # files of bias 1 as before
    path = save_genome(tmp_path / "half.json", g, half)
    assert json.loads(path.read_text())["layout"]["bias_value"] == 0.5
    assert torch.equal(load_genome(path, half).weight[0, 0], g.weight[0, 0])
    with pytest.raises(CheckpointError, match="bias_value 0.5 does not match the config's 1.0"):
        load_genome(path, cfg)
    with pytest.raises(CheckpointError, match="bias_value 1.0 does not match the config's 0.5"):
        load_genome(save_genome(tmp_path / "one.json", g, cfg), half)


def test_truncated_genome_file(tmp_path):
    cfg = small_config()
    g, _ = population(cfg)
    path = save_genome(tmp_path / "g.json", g, cfg)
    path.write_text(path.read_text()[:40])
    with pytest.raises(CheckpointError, match="not valid JSON"):
        load_genome(path, cfg)


def test_sigmoid_phenotype_computes_a_hand_wired_xor():
    cfg = small_config(pop_size=2, max_hidden=2, feed_forward=True)
    N = cfg.num_nodes  # 0, 1 inputs; 2 bias; 3 output; 4, 5 hidden
    conn = torch.zeros(1, 1, N, N, dtype=torch.bool)
    weight = torch.zeros(1, 1, N, N)
    for i, j, w in [(0, 4, 2.0), (1, 4, 2.0), (2, 4, -1.0), (0, 5, 2.0), (1, 5, 2.0), (2, 5, -3.0),
                    (4, 3, 2.0), (5, 3, -4.0), (2, 3, -0.5)]:
        conn[0, 0, i, j], weight[0, 0, i, j] = True, w
    node = torch.zeros(1, 1, N, dtype=torch.bool)
    node[..., :6] = True
    g = Genomes(weight, conn, conn.clone(), node, torch.ones(1, 1))
    x = torch.tensor([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    # The genome as a one-network layer; the 4 input rows all run network 0, two updates
    # (the depth of the XOR net) from node values 0.
    net = PopulationRecurrentSigmoid(g.weight.reshape(1, N, N), g.enabled.reshape(1, N, N),
                                     num_clamped=cfg.num_inputs, num_bias=cfg.num_bias)
    rows = torch.zeros(4, dtype=torch.int64)
    out = net.control_step(x, updates=2, network=rows)[:, cfg.first_output]

    def s(v):
        return 1 / (1 + math.exp(-4.9 * v))

    expected = []
    for a, b in x.tolist():
        h1, h2 = s(2 * a + 2 * b - 1), s(2 * a + 2 * b - 3)
        expected.append(s(2 * h1 - 4 * h2 - 0.5))
    expected = torch.tensor(expected)
    torch.testing.assert_close(out, expected)
    # The genome's controller: the same network, force F = 10 (2 y - 1) from the output y.
    controller = SigmoidController(g, cfg, SigmoidSpec(updates_per_step=2), action_max=10.0, observation_size=2)
    action, _, values = controller.act(x, controller.initial_state(rows))
    assert torch.equal(values[:, controller.outputs[0]], out)
    torch.testing.assert_close(action[:, 0], 10.0 * (2.0 * expected - 1.0))


def test_spiking_phenotype_equals_the_snn_torch_layer():
    cfg = small_config(num_bias=0, node_add_prob=0.8, conn_add_prob=0.8, pop_size=5)
    g = _grown(cfg, rounds=4)
    with torch.no_grad():
        g.weight.mul_(20.0)
    N = cfg.num_nodes
    obs01 = torch.rand(10, 2)  # normalised inputs of the 2 x 5 genomes
    # The controller: input k gets 15 * x_k (mV/ms), every neuron 4 mV/ms; a spike adds the weight
    # (mV/ms) for one 0.5 ms substep (synapse_kick_mv = dt_ms); one control step is 40 substeps.
    spec = SpikingSpec(dt_ms=0.5, i_background=4.0, i_input_max=15.0, synapse_kick_mv=0.5)
    controller = SpikingController(g, cfg, spec, period_s=0.02, action_max=10.0, observation_size=2)
    assert controller.substeps == 40
    rows = torch.arange(10)
    _, state, counts = controller.act(obs01, controller.initial_state(rows))
    # The same networks through snn_torch directly, over every node slot.
    w = masked_weights(g.weight.reshape(10, N, N), g.enabled.reshape(10, N, N))
    i_ext = torch.full((40, 10, N), 4.0)
    i_ext[..., :2] += 15.0 * obs01
    z, _ = recurrent_izhikevich_run(i_ext, recurrent_init((10, N), QIU2019), w, QIU2019)
    # Each network simulates its own genome's nodes, in slot order (node_slots; -1 pads).
    slots = controller.node_slots
    valid = slots >= 0
    assert torch.equal(counts[valid], z.sum(0).gather(1, slots.clamp(min=0))[valid])
    assert counts.sum() > 0 and bool((~valid).any())  # the genomes differ in size: some networks are padded
    # ... and through the population layer's control step (C kernel and torch step).
    i_step = torch.zeros(10, N)
    i_step[:, :2] = 15.0 * obs01
    for backend in ("auto", "torch"):
        layer = PopulationRecurrentIzhikevich(g.weight.reshape(10, N, N), g.enabled.reshape(10, N, N), QIU2019,
                                              i_background=4.0, backend=backend)
        full, layer_state = layer.control_step(i_step, substeps=40)
        assert torch.equal(full, z.sum(0)), backend
        # State persists across control steps until reset (a fresh initial state).
        more, _ = layer.control_step(i_step, layer_state, substeps=40)
        again, _ = layer.control_step(i_step, layer.initial_state(i_step), substeps=40)
        assert torch.equal(again, full) and not torch.equal(more, full), backend
    # The controller's state persists the same way.
    _, _, more = controller.act(obs01, state)
    _, _, again = controller.act(obs01, controller.initial_state(rows))
    assert torch.equal(again, counts) and not torch.equal(more, counts)


def test_a_float32_sigma_clamped_to_its_bound_loads_again(tmp_path):
    # float32(1e-5) is 9.99999975e-06, below the float64 bound: a genome clamped there (as weight
    # search clamps) must still load; a value beyond the float32-rounded bound must not
    from dataclasses import replace as _replace

    cfg = _replace(small_config(), sigma_min_value=1e-5)
    g, _ = population(cfg)
    g.sigma[0, 0] = torch.tensor(1e-5, dtype=torch.float32)
    assert float(g.sigma[0, 0]) < 1e-5
    back = load_genome(save_genome(tmp_path / "edge.json", g, cfg), cfg)
    assert torch.equal(back.sigma[0, 0], g.sigma[0, 0])
    g.sigma[0, 0] = 9e-6
    with pytest.raises(CheckpointError, match="sigma_min_value"):
        load_genome(save_genome(tmp_path / "below.json", g, cfg), cfg)
