import pytest
import torch

from snn_torch import PopulationRecurrentIzhikevich
from snn_torch.functional import (
    QIU2019,
    masked_weights,
    recurrent_init,
    recurrent_izhikevich_run,
    recurrent_izhikevich_step,
)
from tests.conftest import DEVICES


def _population(P=7, N=6, seed=0, density=0.4, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    weight = (torch.randn(P, N, N, generator=g) * 8.0).to(dtype)
    mask = torch.rand(P, N, N, generator=g) < density
    current = (torch.rand(200, P, N, generator=g) * 12.0).to(dtype)
    return weight, mask, current


def test_population_equals_each_network_alone():
    weight, mask, current = _population()
    layer = PopulationRecurrentIzhikevich(weight, mask, i_background=2.0)
    z_all, s_all = layer(current)
    assert z_all.sum() > 50
    for p in range(weight.shape[0]):
        alone = PopulationRecurrentIzhikevich(weight[p:p + 1], mask[p:p + 1], i_background=2.0)
        z, s = alone(current[:, p:p + 1])
        assert torch.equal(z[:, 0], z_all[:, p])
        assert torch.equal(s.v[0], s_all.v[p])  # bitwise, on CPU


def test_extra_batch_axis_equals_separate_runs():
    weight, mask, current = _population(P=3, N=4)
    w_eff = masked_weights(weight, mask)
    two = torch.stack([current, current.flip(0)], dim=2)  # [T, P, B=2, N]
    z2, _ = recurrent_izhikevich_run(two, recurrent_init(two.shape[1:], QIU2019), w_eff, QIU2019)
    for b, cur in enumerate([current, current.flip(0)]):
        z1, _ = recurrent_izhikevich_run(cur, recurrent_init(cur.shape[1:], QIU2019), w_eff, QIU2019)
        assert torch.equal(z2[:, :, b], z1)


@pytest.mark.parametrize("huge", [1e6, float("inf"), float("nan")])
def test_masked_out_connections_have_no_effect(huge):
    weight, mask, current = _population()
    z_ref, _ = PopulationRecurrentIzhikevich(weight, mask)(current)
    blown = torch.where(mask, weight, torch.full_like(weight, huge))
    z, _ = PopulationRecurrentIzhikevich(blown, mask)(current)
    assert torch.equal(z, z_ref)


def test_connection_carries_spikes_with_one_step_delay():
    # Neuron 0 is driven; 0 -> 1 is strong; neuron 1 gets no external input.
    weight = torch.zeros(1, 2, 2)
    weight[0, 0, 1] = 400.0
    mask = torch.zeros(1, 2, 2, dtype=torch.bool)
    mask[0, 0, 1] = True
    current = torch.zeros(100, 1, 2)
    current[:, 0, 0] = 15.0
    z, _ = PopulationRecurrentIzhikevich(weight, mask)(current)
    t0 = torch.nonzero(z[:, 0, 0])[0].item()
    assert z[:, 0, 1].sum() > 0
    assert torch.nonzero(z[:, 0, 1])[0].item() == t0 + 1
    # Without the mask bit the same weight does nothing.
    z_off, _ = PopulationRecurrentIzhikevich(weight, torch.zeros_like(mask))(current)
    assert z_off[:, 0, 1].sum() == 0


def test_self_connection_sustains_activity():
    weight = torch.full((1, 1, 1), 300.0)
    mask = torch.ones(1, 1, 1, dtype=torch.bool)
    kick = torch.zeros(200, 1, 1)
    kick[:10] = 40.0  # brief drive, then nothing
    z_loop, _ = PopulationRecurrentIzhikevich(weight, mask)(kick)
    z_none, _ = PopulationRecurrentIzhikevich(weight, ~mask)(kick)
    assert z_loop[50:].sum() > 0 and z_none[50:].sum() == 0


def test_run_equals_steps_bitwise_and_state_carries():
    weight, mask, current = _population()
    layer = PopulationRecurrentIzhikevich(weight, mask)
    z_all, s_all = layer(current)
    z1, s1 = layer(current[:80])
    z2, s2 = layer(current[80:], s1)
    assert torch.equal(z_all, torch.cat([z1, z2]))
    assert torch.equal(s_all.v, s2.v) and torch.equal(s_all.z, s2.z)
    w_eff = masked_weights(weight, mask)
    state = recurrent_init(current.shape[1:], QIU2019)
    for t in range(current.shape[0]):
        z, state = recurrent_izhikevich_step(current[t], state, w_eff, QIU2019)
        assert torch.equal(z, z_all[t])


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dtype_and_device_are_preserved(device, dtype):
    weight, mask, current = _population(dtype=dtype)
    layer = PopulationRecurrentIzhikevich(weight, mask).to(device)
    z, s = layer(current.to(device))
    for t in (z, s.v, s.u, s.z):
        assert t.dtype == dtype and t.device.type == device


def test_trainable_weights_receive_gradients_through_the_surrogate():
    from snn_torch import fast_sigmoid

    weight, mask, current = _population(P=2, N=4)
    layer = PopulationRecurrentIzhikevich(weight, mask, trainable=True, spike_fn=fast_sigmoid())
    z, _ = layer(current[:50])
    z.sum().backward()
    grad = layer.weight.grad
    assert grad is not None and bool(torch.isfinite(grad).all())
    assert grad[mask].abs().sum() > 0 and grad[~mask].abs().sum() == 0


def test_bad_weights_masks_and_currents_are_rejected():
    weight, mask, current = _population(P=3, N=4)
    with pytest.raises(ValueError, match="mask must have weight's shape"):
        PopulationRecurrentIzhikevich(weight, mask[:, :3])
    with pytest.raises(ValueError, match="mask must be a bool"):
        PopulationRecurrentIzhikevich(weight, mask.float())
    with pytest.raises(ValueError, match=r"weight must be a \[P, N, N\]"):
        PopulationRecurrentIzhikevich(weight[:, :3], mask[:, :3])
    layer = PopulationRecurrentIzhikevich(weight, mask)
    with pytest.raises(ValueError, match="i_ext must be"):
        layer(current[:, :2])
    with pytest.raises(ValueError, match="i_ext must be"):
        layer(current[0])
    bad = current.clone()
    bad[5, 1, 2] = float("nan")
    with pytest.raises(ValueError, match="i_ext holds NaN"):
        layer(bad)
    nan_w = weight.clone()
    nan_w[mask] = float("nan")
    with pytest.raises(ValueError, match="weights hold NaN"):
        PopulationRecurrentIzhikevich(nan_w, mask)(current)
    state = recurrent_init((3, 4), QIU2019)
    with pytest.raises(ValueError, match="weights must be"):
        recurrent_izhikevich_step(current[0], state, torch.zeros(3, 5, 5), QIU2019)
