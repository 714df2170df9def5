"""The fused Izhikevich step: izhikevich_step's bits forward, its exact gradient backward, less memory."""

import pytest
import torch

from snn_torch import Izhikevich
from snn_torch.functional import (
    QIU2019,
    REGULAR_SPIKING,
    IzhikevichParams,
    IzhikevichState,
    fast_sigmoid,
    izhikevich_init,
    izhikevich_step,
)
from snn_torch.functional.izhikevich_fused import _IzhikevichStep, fused_applies, izhikevich_step_fused

COMBOS = [("heun", True), ("heun", False), ("euler", True), ("euler", False)]
PER_NEURON = IzhikevichParams(a=torch.tensor([0.02, 0.1, 0.02]), b=torch.tensor([0.2, 0.2, 0.25]),
                              c=torch.tensor([-65.0, -50.0, -55.0]), d=torch.tensor([8.0, 2.0, 4.0]),
                              v_peak=torch.tensor([30.0, 30.0, 25.0]))


def _settled(shape, p, dtype, seed=0, steps=40):
    """A state mid-activity (some neurons near spiking, some just reset)."""
    g = torch.Generator().manual_seed(seed)
    state = izhikevich_init(shape, p, dtype=dtype)
    for _ in range(steps):
        _, state = izhikevich_step(torch.rand(shape, generator=g, dtype=dtype) * 30, state, p)
    return state


@pytest.mark.parametrize("method,substep_reset", COMBOS)
@pytest.mark.parametrize("p", [QIU2019, PER_NEURON], ids=["floats", "per-neuron"])
def test_forward_equals_izhikevich_step_bitwise(method, substep_reset, p):
    g = torch.Generator().manual_seed(3)
    plain = fused = izhikevich_init((16, 3), p)
    spikes = 0.0
    for t in range(300):
        scale = 1e5 if t % 50 == 49 else 40.0  # now and then an absurd current: the NaN/overflow path
        i = (torch.rand(16, 3, generator=g) - 0.1) * scale
        kw = dict(method=method, substep_reset=substep_reset, dt_ms=0.5)
        z1, plain = izhikevich_step(i, plain, p, **kw)
        z2, fused = izhikevich_step_fused(i, fused, p, **kw)
        assert torch.equal(z1, z2) and torch.equal(plain.v, fused.v) and torch.equal(plain.u, fused.u), t
        spikes += z1.sum().item()
    assert spikes > 300


@pytest.mark.parametrize("method,substep_reset", COMBOS)
def test_gradcheck_float64(method, substep_reset):
    state = _settled((4, 3), PER_NEURON, torch.float64, seed=1)
    p = IzhikevichParams(*(t.double() for t in PER_NEURON))
    i = (torch.rand(4, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64) * 60).requires_grad_()
    v, u = (t.clone().requires_grad_() for t in state)
    x, _, _ = _IzhikevichStep.apply(i, v, u, p, 0.5, method == "heun", substep_reset)
    assert (x >= 0).any() and (x < 0).any()  # both branches are checked
    assert torch.autograd.gradcheck(
        lambda i, v, u: _IzhikevichStep.apply(i, v, u, p, 0.5, method == "heun", substep_reset),
        (i, v, u), eps=1e-7, atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("method,substep_reset", COMBOS)
def test_gradient_equals_autograd_of_izhikevich_step(method, substep_reset):
    spike_fn = fast_sigmoid()
    state = _settled((8, 3), PER_NEURON, torch.float64, seed=4)
    p = IzhikevichParams(*(t.double() for t in PER_NEURON))
    g = torch.Generator().manual_seed(5)
    i = (torch.rand(8, 3, generator=g, dtype=torch.float64) * 60).requires_grad_()
    v, u = (t.clone().requires_grad_() for t in state)
    w = torch.randn(3, 8, 3, generator=g, dtype=torch.float64)
    grads = []
    for step in (izhikevich_step, izhikevich_step_fused):
        z, (vn, un) = step(i, IzhikevichState(v, u), p, method=method, substep_reset=substep_reset, spike_fn=spike_fn)
        loss = (z * w[0]).sum() + (vn * w[1]).sum() + (un * w[2]).sum()
        grads.append(torch.autograd.grad(loss, (i, v, u)))
    assert 0 < z.sum() < z.numel()
    for a, b in zip(*grads, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_layer_fused_equals_unfused_and_saves_less():
    torch.manual_seed(0)
    layers = [Izhikevich(5, 7, fused=f) for f in (True, False)]
    layers[1].load_state_dict(layers[0].state_dict())
    with torch.no_grad():
        for layer in layers:
            layer.linear.weight.mul_(40.0)
    x = torch.rand(30, 4, 5)
    outs, saved = [], []
    for layer in layers:
        sizes = {}

        def pack(t, sizes=sizes):
            sizes[t.untyped_storage().data_ptr()] = t.untyped_storage().nbytes()
            return t

        with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
            z, state = layer(x)
        (z * torch.linspace(-1, 1, 7)).sum().backward()
        outs.append((z, state, layer.linear.weight.grad))
        saved.append(sum(sizes.values()))
    (z1, s1, g1), (z2, s2, g2) = outs
    assert torch.equal(z1, z2) and torch.equal(s1.v, s2.v) and z1.sum() > 10
    torch.testing.assert_close(g1, g2, rtol=1e-4, atol=1e-5)
    assert saved[0] < saved[1] / 2, saved


def test_fused_steps_aside_for_learned_parameters_and_compile_and_dtype_mismatch():
    state = izhikevich_init((2, 3), REGULAR_SPIKING)
    i = torch.ones(2, 3)
    assert fused_applies(i, state, REGULAR_SPIKING, "heun")
    learned = REGULAR_SPIKING._replace(a=torch.tensor(0.02, requires_grad=True))
    assert not fused_applies(i, state, learned, "heun")
    assert not fused_applies(i, state, REGULAR_SPIKING._replace(b=torch.tensor(0.2, dtype=torch.float64)), "heun")
    layer = Izhikevich(3, 2, learn_params=["a", "d"])
    layer(torch.rand(20, 1, 3) * 5)[0].sum().backward()
    assert layer.a.grad is not None and layer.d.grad is not None and layer.c.grad is None
