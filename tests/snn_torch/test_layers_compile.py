"""Every layer's forward compiles with no graph break (fullgraph=True) and equals eager."""

import pytest
import torch

from snn_torch import (
    LI,
    LIF,
    ConstantCurrentEncoder,
    Izhikevich,
    IzhikevichCell,
    IzhikevichRecurrent,
    LatencyEncoder,
    LICell,
    LIFCell,
    LIFRecurrent,
    RateEncoder,
)

LAYERS = {
    "Izhikevich": lambda: Izhikevich(3, 4),
    "IzhikevichRecurrent": lambda: IzhikevichRecurrent(3, 4),
    "LIF": lambda: LIF(3, 4),
    "LIFRecurrent": lambda: LIFRecurrent(3, 4),
    "LI": lambda: LI(3, 4),
}
CELLS = {"IzhikevichCell": IzhikevichCell, "LIFCell": LIFCell, "LICell": LICell}


def _drive(layer):
    with torch.no_grad():
        layer.linear.weight.fill_(0.0)
        layer.linear.bias.fill_(30.0 if "Izhikevich" in type(layer).__name__ else 1.5)
    return torch.rand(4, 2, 3, generator=torch.Generator().manual_seed(0))


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_layer_compiles_fullgraph_and_equals_eager(name):
    """Forward equal to eager; for Izhikevich also the backward (AOT autograd traces it: the plain
    step under compile, the fused one in eager)."""
    torch._dynamo.reset()
    torch.manual_seed(0)
    layer = LAYERS[name]()
    x = _drive(layer)
    # A warm state near threshold, so four steps already spike (and validation of a given state compiles).
    _, state = layer(torch.cat([x] * 5))
    state = type(state)(*(t.detach() for t in state))
    backend = "aot_eager" if name == "Izhikevich" else "eager"
    compiled = torch.compile(layer, fullgraph=True, backend=backend)
    readout = torch.linspace(-1, 1, 4)
    results = []
    for model in (compiled, layer):
        layer.zero_grad()
        out, final = model(x, state)
        (out * readout).sum().backward()
        results.append((out, final, layer.linear.bias.grad.clone()))
    (out_c, state_c, grad_c), (out_e, state_e, grad_e) = results
    torch.testing.assert_close(out_c, out_e, rtol=0, atol=0)
    for a, b in zip(state_c, state_e, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    torch.testing.assert_close(grad_c, grad_e, rtol=1e-5, atol=1e-6)
    if name != "LI":
        assert out_e.sum() > 0
    assert grad_e.abs().sum() > 0


@pytest.mark.parametrize("name", sorted(CELLS))
def test_cell_compiles_fullgraph(name):
    torch._dynamo.reset()
    cell = CELLS[name]()
    i = torch.full((2, 4), 20.0)
    _, state = cell(i)
    compiled = torch.compile(cell, fullgraph=True, backend="eager")
    for a, b in zip(compiled(i, state), cell(i, state), strict=True):
        if isinstance(a, torch.Tensor):
            torch.testing.assert_close(a, b, rtol=0, atol=0)


def test_encoders_compile_fullgraph():
    torch._dynamo.reset()
    x = torch.rand(2, 3)
    for enc in (LatencyEncoder(5), ConstantCurrentEncoder(5, gain=2.0)):
        torch.testing.assert_close(torch.compile(enc, fullgraph=True, backend="eager")(x), enc(x))
    spikes = torch.compile(RateEncoder(500, f_max_hz=500.0), fullgraph=True, backend="eager")(x)
    assert spikes.shape == (500, 2, 3) and set(spikes.unique().tolist()) <= {0.0, 1.0}
    torch.testing.assert_close(spikes.mean(0), x * 0.5, atol=0.1, rtol=0)  # 500 Hz at 1 ms: p = x / 2
