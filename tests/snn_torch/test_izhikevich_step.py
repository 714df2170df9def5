import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from snn_torch import Izhikevich, IzhikevichCell
from snn_torch.functional import (
    PRESETS,
    QIU2019,
    REGULAR_SPIKING,
    IzhikevichParams,
    IzhikevichState,
    izhikevich_init,
    izhikevich_run,
    izhikevich_step,
)
from tests.conftest import DEVICES


def _drive(steps=300, n=6, seed=0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(steps, n, generator=g) * 30.0).to(dtype)


@pytest.mark.parametrize("method", ["heun", "euler"])
@pytest.mark.parametrize("substep_reset", [True, False])
def test_run_equals_repeated_steps_bitwise(method, substep_reset):
    current = _drive()
    kw = dict(dt_ms=0.5, method=method, substep_reset=substep_reset)
    state0 = izhikevich_init((6,), QIU2019)
    z_all, s_all = izhikevich_run(current, state0, QIU2019, **kw)
    state, zs = state0, []
    for t in range(current.shape[0]):
        z, state = izhikevich_step(current[t], state, QIU2019, **kw)
        zs.append(z)
    assert torch.equal(z_all, torch.stack(zs))
    assert torch.equal(s_all.v, state.v) and torch.equal(s_all.u, state.u)
    assert z_all.sum() > 10  # the drive really makes spikes


def test_layer_over_time_equals_calls_carrying_state_bitwise():
    torch.manual_seed(0)
    layer = Izhikevich(3, 5)
    with torch.no_grad():
        layer.linear.weight.mul_(30.0)
        layer.linear.bias.fill_(5.0)
    x = torch.rand(40, 2, 3)
    z_all, s_all = layer(x)
    state, zs = None, []
    for chunk in torch.split(x, [1, 7, 12, 20]):
        z, state = layer(chunk, state)
        zs.append(z)
    assert torch.equal(z_all, torch.cat(zs))
    assert torch.equal(s_all.v, state.v) and torch.equal(s_all.u, state.u)
    assert z_all.sum() > 0


def test_cell_matches_functional_step():
    cell = IzhikevichCell(REGULAR_SPIKING, dt_ms=0.25)
    current = _drive(50, 4)
    state_c, state_f = None, izhikevich_init((4,), REGULAR_SPIKING)
    for t in range(50):
        z_c, state_c = cell(current[t], state_c)
        z_f, state_f = izhikevich_step(current[t], state_f, REGULAR_SPIKING, dt_ms=0.25)
        assert torch.equal(z_c, z_f)
    assert torch.equal(state_c.v, state_f.v)


def test_presets_have_their_classic_behaviour():
    """Under I = 10 for 500 ms: FS fires fastest, RS adapts, CH fires in bursts."""
    names = ["regular_spiking", "fast_spiking", "chattering"]
    p = IzhikevichParams(*(torch.tensor([PRESETS[n][k] for n in names]) for k in range(4)))
    z, _ = izhikevich_run(torch.full((1000, 3), 10.0), izhikevich_init((3,), p), p)
    counts = dict(zip(names, z.sum(0).tolist(), strict=True))
    assert counts["fast_spiking"] > counts["chattering"] > counts["regular_spiking"] > 0
    isi = {n: torch.diff(torch.nonzero(z[:, j]).flatten()).float() for j, n in enumerate(names)}
    assert isi["regular_spiking"][-1] > 1.5 * isi["regular_spiking"][0]  # adaptation
    assert isi["chattering"].min() * 4 < isi["chattering"].max()  # bursts: short and long gaps


def test_no_input_no_spikes():
    z, state = izhikevich_run(torch.zeros(2000, 3), izhikevich_init((3,), QIU2019), QIU2019)
    assert z.sum() == 0
    assert torch.allclose(state.v, torch.full((3,), -70.0), atol=0.5)  # rest of b=0.2 is -70 mV


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dtype_and_device_are_preserved(device, dtype):
    cell = IzhikevichCell()
    current = torch.full((4,), 12.0, dtype=dtype, device=device)
    z, state = cell(current)
    for t in (z, state.v, state.u):
        assert t.dtype == dtype and t.device.type == device
    layer = Izhikevich(2, 3, device=device, dtype=dtype)
    z, state = layer(torch.rand(5, 1, 2, dtype=dtype, device=device))
    for t in (z, state.v, state.u):
        assert t.dtype == dtype and t.device.type == device


def test_per_neuron_tensor_parameters_broadcast():
    p = IzhikevichParams(a=torch.tensor([[0.02, 0.1]]), b=0.2, c=torch.tensor([[-65.0, -65.0]]), d=torch.tensor([[8.0, 2.0]]))
    z, _ = izhikevich_run(torch.full((400, 3, 2), 10.0), izhikevich_init((3, 2), p), p)
    alone_rs, _ = izhikevich_run(torch.full((400, 3), 10.0), izhikevich_init((3,), REGULAR_SPIKING), REGULAR_SPIKING)
    assert torch.equal(z[..., 0], alone_rs)
    assert z[..., 1].sum() > z[..., 0].sum()


@settings(max_examples=40, deadline=None)
@given(current=st.floats(min_value=-1e6, max_value=1e6), dt=st.sampled_from([0.1, 0.5, 1.0]),
       method=st.sampled_from(["heun", "euler"]))
def test_state_stays_finite_for_any_finite_current(current, dt, method):
    z, state = izhikevich_run(torch.full((50, 2), current), izhikevich_init((2,), QIU2019), QIU2019,
                              dt_ms=dt, method=method)
    assert bool(torch.isfinite(state.v).all() and torch.isfinite(state.u).all())
    assert bool(((z == 0) | (z == 1)).all())


# ---- bad input -------------------------------------------------------------------------

@pytest.mark.parametrize("dt", [0.0, -0.5, float("nan"), float("inf"), "1", None])
def test_bad_dt_is_rejected(dt):
    state = izhikevich_init((3,), QIU2019)
    with pytest.raises(ValueError, match="dt_ms"):
        izhikevich_step(torch.zeros(3), state, QIU2019, dt_ms=dt)
    with pytest.raises(ValueError, match="dt_ms"):
        IzhikevichCell(dt_ms=dt)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_current_is_rejected(bad):
    state = izhikevich_init((3,), QIU2019)
    current = torch.tensor([1.0, bad, 2.0])
    with pytest.raises(ValueError, match="i_in"):
        izhikevich_step(current, state, QIU2019)
    with pytest.raises(ValueError, match="i_in"):
        izhikevich_run(current.expand(4, -1), state, QIU2019)
    with pytest.raises(ValueError, match="x holds NaN"):
        Izhikevich(3, 2)(current.expand(4, 1, -1))


def test_non_finite_check_can_be_turned_off():
    state = izhikevich_init((1,), QIU2019)
    izhikevich_step(torch.tensor([float("nan")]), state, QIU2019, validate=False)


def test_mismatched_shapes_dtypes_and_methods_are_rejected():
    state = izhikevich_init((3,), QIU2019)
    with pytest.raises(ValueError, match="i_in has shape"):
        izhikevich_step(torch.zeros(4), state, QIU2019)
    with pytest.raises(ValueError, match="i_in has shape"):
        izhikevich_step(torch.zeros(2, 3), state, QIU2019)  # would grow the state
    with pytest.raises(ValueError, match="dtype"):
        izhikevich_step(torch.zeros(3, dtype=torch.float64), state, QIU2019)
    with pytest.raises(ValueError, match="method"):
        izhikevich_step(torch.zeros(3), state, QIU2019, method="rk45")
    with pytest.raises(ValueError, match=r"i_in\[t\] has shape"):
        izhikevich_run(torch.zeros(5, 4), state, QIU2019)
    with pytest.raises(ValueError, match=r"\[T, \.\.\., 3\]"):
        Izhikevich(3, 2)(torch.zeros(5, 4))
    with pytest.raises(ValueError, match="IzhikevichParams.c"):
        IzhikevichCell(IzhikevichParams(0.02, 0.2, float("nan"), 2.0))


def test_state_is_explicit_and_not_stored():
    cell = IzhikevichCell()
    z1, s1 = cell(torch.full((2,), 20.0))
    z2, s2 = cell(torch.full((2,), 20.0))
    assert torch.equal(s1.v, s2.v)  # second call started from rest again
    assert isinstance(s1, IzhikevichState)
    assert len(list(cell.buffers())) == 0
