"""A spiking controller's control step in one C call equals its torch modules, bit for bit."""

import pytest
import torch

from evolution import NEATConfig, SpikingSpec
from evolution.phenotype import SpikingController
from evolution.population import Genomes
from snn_torch.kernels.network import kernel_available

pytestmark = pytest.mark.skipif(not kernel_available(), reason="no C compiler: the kernel path does not exist")


def _genomes(G: int, inputs: int, outputs: int, hidden: int, dtype: torch.dtype, seed: int = 0):
    n = inputs + outputs + hidden
    cfg = NEATConfig(num_inputs=inputs, num_outputs=outputs, num_bias=0, max_hidden=hidden, pop_size=G)
    g = torch.Generator().manual_seed(seed)
    conn = torch.rand(1, G, n, n, generator=g) < 0.5
    conn[..., :, :inputs] = False  # nothing drives the input nodes
    weight = (torch.randn(1, G, n, n, generator=g) * 3.0).to(dtype)
    sigma = (torch.rand(1, G, generator=g) * 0.02 + 0.001).to(dtype)
    return Genomes(weight=weight, conn=conn, enabled=conn.clone(), node=torch.ones(1, G, n, dtype=torch.bool),
                   sigma=sigma), cfg


def _run(controller, obs, network, steps, keep_at=None):
    """Actions, counts and the final state over ``steps`` control steps; rows ``keep_at[1]`` kept
    from step ``keep_at[0]`` on (as a rollout compacts)."""
    state = controller.initial_state(network)
    actions, counts = [], []
    for t in range(steps):
        if keep_at is not None and t == keep_at[0]:
            state = controller.select(state, keep_at[1])
            obs = obs[:, keep_at[1]]
        action, state, c = controller.act(obs[t], state)
        actions.append(action.clone())
        counts.append(c.clone())
    return actions, counts, state


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("spec", [
    SpikingSpec(),
    SpikingSpec(decoder="linear", rate_window_steps=3, rest_relative=True),
    SpikingSpec(encoder="bernoulli", decoder="bang_bang", rate_window_steps=1, rest_relative=True),
    SpikingSpec(encoder="bernoulli", input_rate_max_hz=600.0, i_background=12.0, synapse_kick_mv=2.5),
], ids=["paper-table2", "linear-rest", "paper-table1", "bernoulli-sigmoid"])
@pytest.mark.parametrize("shape", [(2, 1, 5), (3, 2, 20)], ids=["n8", "n25-two-actions"])
def test_kernel_step_equals_the_modules(dtype, spec, shape):
    inputs, outputs, hidden = shape
    genomes, cfg = _genomes(11, inputs, outputs, hidden, dtype, seed=hidden)
    common = dict(period_s=0.01, action_max=3.0, observation_size=inputs, action_size=outputs)
    kernel = SpikingController(genomes, cfg, spec, backend="auto", **common)
    reference = SpikingController(genomes, cfg, spec, backend="torch", **common)
    network = torch.arange(11).repeat_interleave(3)  # three episodes per genome
    obs = torch.rand(12, len(network), inputs, generator=torch.Generator().manual_seed(5), dtype=dtype)
    keep = torch.tensor([0, 4, 5, 17, 30, 32])
    a_k, c_k, s_k = _run(kernel, obs, network, 12, keep_at=(7, keep))
    a_t, c_t, s_t = _run(reference, obs, network, 12, keep_at=(7, keep))
    for t in range(12):
        assert torch.equal(a_k[t], a_t[t]), f"actions differ at step {t}"
        assert torch.equal(c_k[t], c_t[t]), f"spike counts differ at step {t}"
    for a, b in zip((*s_k.neurons, s_k.window.history), (*s_t.neurons, s_t.window.history), strict=True):
        assert torch.equal(a, b)
    assert s_k.window.steps == s_t.window.steps == 12
    assert sum(int(c.sum()) for c in c_k) > 0  # the networks spiked: the comparison had something to compare


def test_kernel_step_checks_observations_and_network_indices():
    genomes, cfg = _genomes(4, 2, 1, 3, torch.float32)
    controller = SpikingController(genomes, cfg, period_s=0.01, action_max=1.0, observation_size=2)
    state = controller.initial_state(torch.arange(4))
    with pytest.raises(ValueError, match=r"observations must be \[4, 2\]"):
        controller.act(torch.rand(4, 3), state)
    bad = controller.initial_state(torch.tensor([0, 1, 2, 3]))
    bad = bad._replace(network=torch.tensor([0, 1, 2, 9]))
    with pytest.raises(ValueError, match=r"network indices must lie in \[0, 4\)"):
        controller.act(torch.rand(4, 2), bad)


def test_rate_control_kernel_refuses_what_it_would_misread():
    from snn_torch.functional.izhikevich import QIU2019
    from snn_torch.kernels.network import RateControlKernel

    w, iconst, w_out = torch.zeros(3, 5, 5), torch.zeros(5), torch.zeros(3, 5, 2)
    common = dict(dt_ms=0.5, substeps=20, gain=60.0, bernoulli=False, rest=None)
    RateControlKernel(w, QIU2019, iconst=iconst, w_out=w_out, **common)  # consistent: accepted
    with pytest.raises(ValueError, match="iconst must be a contiguous CPU tensor of torch.float32"):
        RateControlKernel(w, QIU2019, iconst=iconst.double(), w_out=w_out, **common)
    with pytest.raises(ValueError, match="w_out must be a contiguous"):
        RateControlKernel(w, QIU2019, iconst=iconst, w_out=torch.zeros(3, 2, 5).transpose(1, 2), **common)
    with pytest.raises(ValueError, match=r"iconst and rest must be \[5\], w_out \[3, 5, K\]"):
        RateControlKernel(w, QIU2019, iconst=torch.zeros(4), w_out=w_out, **common)
    with pytest.raises(ValueError, match="N <= 64"):
        RateControlKernel(torch.zeros(1, 65, 65), QIU2019, iconst=torch.zeros(65), w_out=torch.zeros(1, 65, 1),
                          **common)


@pytest.mark.parametrize("backend", ["auto", "torch"])
def test_each_network_simulates_its_own_nodes_and_equals_itself_alone(backend):
    # Genome g uses hidden slot 3 + g only: the batch's slots are all 3 + 6, each genome's 3 + 1.
    inputs, outputs, hidden = 2, 1, 6
    genomes, cfg = _genomes(6, inputs, outputs, hidden, torch.float32, seed=11)
    node = torch.zeros(1, 6, 9, dtype=torch.bool)
    node[..., :3] = True
    node[0, torch.arange(6), 3 + torch.arange(6)] = True
    conn = genomes.conn & node.unsqueeze(-1) & node.unsqueeze(-2)
    genomes = type(genomes)(weight=genomes.weight, conn=conn, enabled=conn.clone(), node=node, sigma=genomes.sigma)
    common = dict(period_s=0.01, action_max=2.0, observation_size=inputs, backend=backend)
    batch = SpikingController(genomes, cfg, **common)
    assert batch.num_local == 4 and len(batch.nodes) == 9
    assert batch.node_slots[:, 3].tolist() == list(range(3, 9))
    obs = torch.rand(6, 6, inputs, generator=torch.Generator().manual_seed(2))
    actions, counts, _ = _run(batch, obs, torch.arange(6), 6)
    for g in range(6):
        alone = SpikingController(genomes.gather(torch.tensor([[g]])), cfg, **common)
        a_alone, c_alone, _ = _run(alone, obs[:, g : g + 1], torch.arange(1), 6)
        assert all(torch.equal(a[g : g + 1], b) for a, b in zip(actions, a_alone, strict=True))
        assert all(torch.equal(c[g : g + 1], d) for c, d in zip(counts, c_alone, strict=True))
    assert sum(float(c[:, 3].sum()) for c in counts) > 0  # the hidden neurons took part
