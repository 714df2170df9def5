import json
import math

import networkx as nx
import pytest
import torch

from evolution.checkpoint import CheckpointError
from evolution.genome_io import genome_to_dict, load_genome, save_genome, to_networkx
from evolution.mutate import mutate_add_connection, mutate_add_node
from evolution.phenotype import SigmoidNetworks, SpikingNetworks
from evolution.population import Genomes
from snn_torch.functional import QIU2019, masked_weights, recurrent_init, recurrent_izhikevich_run
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
    out = SigmoidNetworks(g, cfg).activate(x.expand(1, 1, 4, 2), updates=2)[..., 0]

    def s(v):
        return 1 / (1 + math.exp(-4.9 * v))

    expected = []
    for a, b in x.tolist():
        h1, h2 = s(2 * a + 2 * b - 1), s(2 * a + 2 * b - 3)
        expected.append(s(2 * h1 - 4 * h2 - 0.5))
    torch.testing.assert_close(out[0, 0], torch.tensor(expected))


def test_spiking_phenotype_equals_the_snn_torch_layer():
    cfg = small_config(num_bias=0, node_add_prob=0.8, conn_add_prob=0.8, pop_size=5)
    g = _grown(cfg, rounds=4)
    with torch.no_grad():
        g.weight.mul_(20.0)
    current = torch.rand(2, 5, 2) * 15.0
    net = SpikingNetworks(g, cfg, i_background=4.0)
    counts = net.step(current, substeps=40)
    # The same networks through snn_torch directly.
    w = masked_weights(g.weight.reshape(10, cfg.num_nodes, cfg.num_nodes), g.enabled.reshape(10, cfg.num_nodes, cfg.num_nodes))
    i_ext = torch.full((40, 10, cfg.num_nodes), 4.0)
    i_ext[..., :2] += current.reshape(10, 2)
    z, _ = recurrent_izhikevich_run(i_ext, recurrent_init((10, cfg.num_nodes), QIU2019), w, QIU2019)
    assert torch.equal(counts.reshape(10, -1), z.sum(0))
    assert counts.sum() > 0
    # State persists across control steps until reset.
    more = net.step(current, substeps=40)
    net.reset()
    again = net.step(current, substeps=40)
    assert torch.equal(again, counts) and not torch.equal(more, counts)
