"""What deep-learning users expect of the layers: errors, registered parameters, record_states,
batch_first, Stateful in nn.Sequential, LIF/LI against closed forms, encoders, recurrent layers."""

import math

import pytest
import torch
from torch import nn

from snn_torch import (
    LI,
    LIF,
    ConstantCurrentEncoder,
    Izhikevich,
    IzhikevichCell,
    IzhikevichRecurrent,
    IzhikevichState,
    LatencyEncoder,
    LIFCell,
    LIFParams,
    LIFRecurrent,
    LIFState,
    LIParams,
    Stateful,
    detach_states,
    reset_states,
)
from snn_torch.functional import li_init, li_step, lif_init, lif_step

# ---- errors named by snn_torch -------------------------------------------------------------


def test_wrong_state_batch_names_the_state_field():
    layer = Izhikevich(3, 4)
    _, state = layer(torch.rand(5, 2, 3))
    with pytest.raises(ValueError, match=r"IzhikevichState.v has shape \(2, 4\), but this input needs \(7, 4\)"):
        layer(torch.rand(5, 7, 3), state)


@pytest.mark.parametrize("make", [lambda: Izhikevich(3, 4), lambda: LIF(3, 4)])
def test_tuple_state_is_a_type_error_naming_the_state_class(make):
    layer = make()
    _, state = layer(torch.rand(5, 2, 3))
    with pytest.raises(TypeError, match=r"state must be a snn_torch\.(IzhikevichState|LIFState).*got tuple"):
        layer(torch.rand(5, 2, 3), tuple(state))


def test_dtype_mismatches_are_named():
    layer = Izhikevich(3, 4)
    with pytest.raises(ValueError, match=r"x has dtype torch.float64, but the layer's parameters are torch.float32"):
        layer(torch.rand(5, 2, 3, dtype=torch.float64))
    _, state = layer(torch.rand(5, 2, 3))
    with pytest.raises(ValueError, match=r"IzhikevichState.u has dtype torch.float64"):
        layer(torch.rand(5, 2, 3), IzhikevichState(state.v, state.u.double()))
    cell = IzhikevichCell()
    with pytest.raises(ValueError, match=r"IzhikevichState.v has dtype torch.float32, but the input is torch.float64"):
        cell(torch.ones(2, dtype=torch.float64), IzhikevichState(torch.zeros(2), torch.zeros(2)))
    with pytest.raises(ValueError, match=r"\[B, T, \.\.\., 3\] \(batch first\)"):
        Izhikevich(3, 4, batch_first=True)(torch.rand(5, 2, 4))


def test_validate_false_skips_the_checks():
    layer = LIF(3, 4, validate=False)
    out, _ = layer(torch.full((2, 1, 3), float("nan")))
    assert out.shape == (2, 1, 4)
    with pytest.raises(ValueError, match="x holds NaN"):
        LIF(3, 4)(torch.full((2, 1, 3), float("nan")))


# ---- parameters ----------------------------------------------------------------------------


def test_neuron_parameters_are_registered_and_follow_to():
    layer = Izhikevich(3, 4)
    assert {"a", "b", "c", "d", "v_peak"} <= set(layer.state_dict())
    assert not any(p.requires_grad for n, p in layer.named_parameters() if "linear" not in n)
    layer = layer.to(torch.float64)
    assert layer.c.dtype == torch.float64 and layer.c.item() == -50.0
    z, state = layer(torch.rand(5, 2, 3, dtype=torch.float64))
    assert state.v.dtype == torch.float64
    given = Izhikevich(3, 4, layer.p._replace(d=nn.Parameter(torch.tensor(2.0))))  # a Parameter is learned
    assert given.d.requires_grad and not given.c.requires_grad
    with pytest.raises(ValueError, match="learn_params names unknown fields"):
        LIF(3, 4, learn_params=["tau"])


def test_learned_lif_parameters_get_gradients():
    torch.manual_seed(0)
    layer = LIF(3, 4, LIFParams(tau_mem_ms=torch.full((4,), 10.0), v_th=torch.full((4,), 1.0)),
                learn_params=["tau_mem_ms", "v_th"])
    out, _ = layer(torch.rand(20, 2, 3) * 3)
    out.sum().backward()
    assert layer.tau_mem_ms.grad.shape == (4,) and layer.tau_mem_ms.grad.abs().sum() > 0
    assert layer.v_th.grad.abs().sum() > 0 and layer.v_leak.grad is None


# ---- record_states, batch_first, Stateful ------------------------------------------------------


@pytest.mark.parametrize("make", [lambda **k: Izhikevich(3, 4, **k), lambda **k: LIF(3, 4, **k),
                                  lambda **k: LI(3, 4, **k), lambda **k: LIFRecurrent(3, 4, **k)])
def test_record_states_and_batch_first(make):
    torch.manual_seed(0)
    base = make()
    x = torch.rand(6, 2, 3) * 40
    out, last = base(x)
    recorder = make(record_states=True)
    recorder.load_state_dict(base.state_dict())
    out_r, states = recorder(x)
    assert torch.equal(out, out_r)
    for field, final in zip(states, last, strict=True):
        assert field.shape == (6, 2, 4) and torch.equal(field[-1], final)
    bf = make(batch_first=True)
    bf.load_state_dict(base.state_dict())
    out_b, last_b = bf(x.transpose(0, 1))
    assert torch.equal(out_b, out.transpose(0, 1)) and torch.equal(last_b[0], last[0])


def test_stateful_in_sequential_carries_resets_and_detaches():
    torch.manual_seed(0)
    model = nn.Sequential(Stateful(LIF(3, 8)), Stateful(LI(8, 2)))
    x = torch.rand(10, 2, 3) * 3
    whole = model(x)
    reset_states(model)
    chunks = torch.cat([model(x[:4]), model(x[4:])])
    assert torch.equal(whole, chunks) and whole.abs().sum() > 0
    reset_states(model)
    assert torch.equal(model(x[:4]), whole[:4])  # starts from rest again
    detach_states(model)
    model(x[4:]).sum().backward()  # the first chunk's graph is not needed any more
    assert model[0].state.v.grad_fn is not None and model[0].layer.linear.weight.grad is not None


# ---- LIF and LI against closed forms -------------------------------------------------------------


def test_lif_fires_at_the_analytic_period():
    """r I = 2 mV from v = 0, v_th = 1 mV, tau 10 ms: v(t) = 2 (1 - exp(-t/10)) crosses at 10 ln 2 = 6.93 ms."""
    p = LIFParams(tau_mem_ms=10.0, v_th=1.0, v_reset=0.0)
    state, spikes = lif_init((1,), p), []
    for _ in range(70):
        z, state = lif_step(torch.full((1,), 2.0), state, p, dt_ms=1.0)
        spikes.append(z.item())
    assert [t for t, s in enumerate(spikes) if s] == [6 + 7 * k for k in range(10)]  # step 6 ends at 7 ms
    cell = LIFCell(p, reset="subtract")
    z, state = cell(torch.full((1,), 2.0), LIFState(torch.full((1,), 0.95)))
    v1 = 2.0 + (0.95 - 2.0) * math.exp(-0.1)
    assert z.item() == 1.0 and state.v.item() == pytest.approx(v1 - 1.0, abs=1e-6)


def test_li_integrates_exactly_for_any_step():
    p = LIParams(tau_mem_ms=5.0, v_leak=-1.0, r=2.0)
    for dt in (0.1, 1.0, 2.5):
        state = li_init((1,), p, dtype=torch.float64)
        for _ in range(round(10.0 / dt)):
            v, state = li_step(torch.full((1,), 3.0, dtype=torch.float64), state, p, dt_ms=dt)
        assert v.item() == pytest.approx(5.0 + (-1.0 - 5.0) * math.exp(-10.0 / 5.0), rel=1e-12)


# ---- encoders and recurrence ------------------------------------------------------------------


def test_latency_and_current_encoders():
    x = torch.tensor([1.0, 0.5, 0.0])
    spikes = LatencyEncoder(5)(x)
    assert spikes.sum(0).tolist() == [1.0, 1.0, 0.0]
    assert spikes[:, 0].argmax().item() == 0 and spikes[:, 1].argmax().item() == 2
    with pytest.raises(ValueError, match="normalised"):
        LatencyEncoder(5)(torch.tensor([1.5]))
    current = ConstantCurrentEncoder(4, gain=10.0, offset=2.0)(x.requires_grad_())
    assert current.shape == (4, 3) and current[3, 1].item() == 7.0
    current.sum().backward()
    assert x.grad.tolist() == [40.0, 40.0, 40.0]


@pytest.mark.parametrize("make", [lambda: LIFRecurrent(3, 5), lambda: IzhikevichRecurrent(3, 5)])
def test_recurrent_weights_act_and_learn(make):
    torch.manual_seed(0)
    layer = make()
    with torch.no_grad():
        layer.linear.bias.fill_(2.0 if isinstance(layer, LIFRecurrent) else 15.0)
        layer.recurrent.weight.zero_()
    x = torch.rand(30, 2, 3)
    silent, _ = layer(x)
    with torch.no_grad():
        layer.recurrent.weight.fill_(-5.0)  # inhibition between spikes slows firing
    inhibited, state = layer(x)
    assert inhibited.sum() < silent.sum()
    assert torch.equal(state.z, inhibited[-1])
    (inhibited * torch.linspace(-1, 1, 5)).sum().backward()
    assert layer.recurrent.weight.grad.abs().sum() > 0
