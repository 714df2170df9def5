import math

import pytest
import torch

from snn_torch.functional import (
    background_current,
    bang_bang_force,
    bernoulli_encode,
    current_encode,
    firing_rate,
    normalize,
    rate_encode,
    weighted_rate_force,
)


def test_normalize_maps_bounds_to_unit_interval_and_clamps():
    x = torch.tensor([-2.4, 0.0, 1.2, 2.4, 5.0])
    torch.testing.assert_close(normalize(x, -2.4, 2.4), torch.tensor([0.0, 0.5, 0.75, 1.0, 1.0]))
    assert normalize(x, -2.4, 2.4, clamp=False)[-1] > 1
    per_channel = normalize(torch.tensor([[0.0, 0.0]]), torch.tensor([-1.0, -4.0]), torch.tensor([1.0, 0.0]))
    torch.testing.assert_close(per_channel, torch.tensor([[0.5, 1.0]]))


@pytest.mark.parametrize("low, high", [(1.0, 1.0), (2.0, -2.0), (float("nan"), 1.0), (0.0, float("inf"))])
def test_normalize_rejects_bad_bounds(low, high):
    with pytest.raises(ValueError, match="low|high"):
        normalize(torch.zeros(3), low, high)


def test_current_encode_is_linear_between_bounds():
    theta = torch.tensor([-0.21, 0.0, 0.21])
    torch.testing.assert_close(current_encode(theta, -0.21, 0.21, i_max=20.0, i_min=4.0), torch.tensor([4.0, 12.0, 20.0]))


def test_bernoulli_encode_is_reproducible_and_has_the_right_mean():
    prob = torch.tensor([0.0, 0.1, 0.5, 1.0])
    a = bernoulli_encode(prob, 20000, generator=torch.Generator().manual_seed(3))
    b = bernoulli_encode(prob, 20000, generator=torch.Generator().manual_seed(3))
    c = bernoulli_encode(prob, 20000, generator=torch.Generator().manual_seed(4))
    assert a.shape == (20000, 4) and torch.equal(a, b) and not torch.equal(a, c)
    mean = a.mean(0)
    assert mean[0] == 0 and mean[3] == 1
    # 5 standard errors of a binomial proportion
    for j in (1, 2):
        p = prob[j].item()
        assert abs(mean[j].item() - p) < 5 * math.sqrt(p * (1 - p) / 20000)


def test_rate_encode_fires_at_the_requested_frequency():
    x = torch.tensor([0.25, 1.0])
    spikes = rate_encode(x, 40000, f_max_hz=200.0, dt_ms=0.5, generator=torch.Generator().manual_seed(0))
    rates = firing_rate(spikes, dt_ms=0.5)
    torch.testing.assert_close(rates, torch.tensor([50.0, 200.0]), atol=5.0, rtol=0)


def test_encoders_reject_bad_input():
    with pytest.raises(ValueError, match="prob"):
        bernoulli_encode(torch.tensor([1.5]), 3)
    with pytest.raises(ValueError, match="prob"):
        bernoulli_encode(torch.tensor([float("nan")]), 3)
    with pytest.raises(ValueError, match="num_steps"):
        bernoulli_encode(torch.tensor([0.5]), -1)
    with pytest.raises(ValueError, match="f_max_hz"):
        rate_encode(torch.tensor([0.5]), 3, f_max_hz=5000.0, dt_ms=1.0)
    with pytest.raises(ValueError, match="normalised"):
        rate_encode(torch.tensor([2.0]), 3, f_max_hz=100.0, dt_ms=1.0)
    with pytest.raises(ValueError, match="std"):
        background_current((3,), 5.0, std=-1.0)


def test_background_current_constant_and_noisy():
    torch.testing.assert_close(background_current((2, 3), 6.5), torch.full((2, 3), 6.5))
    noisy = background_current((50000,), 6.5, std=2.0, generator=torch.Generator().manual_seed(0),
                               dtype=torch.float64)
    assert abs(noisy.mean().item() - 6.5) < 0.05 and abs(noisy.std().item() - 2.0) < 0.05


def test_firing_rate_in_hz():
    spikes = torch.zeros(200, 2)
    spikes[::10, 0] = 1  # every 10 steps of 0.5 ms = every 5 ms = 200 Hz
    torch.testing.assert_close(firing_rate(spikes, dt_ms=0.5), torch.tensor([200.0, 0.0]))
    with pytest.raises(ValueError, match="no time steps"):
        firing_rate(torch.zeros(0, 2), dt_ms=1.0)
    with pytest.raises(ValueError, match="dt_ms"):
        firing_rate(spikes, dt_ms=0.0)


def test_weighted_rate_force_is_the_papers_equation():
    rates = torch.tensor([[100.0, 20.0], [0.0, 0.0], [10.0, 400.0]])
    w = torch.tensor([0.5, -1.0])
    sigma = torch.tensor([0.1, 2.0, 0.01])
    drive = [0.1 * (50.0 - 20.0), 0.0, 0.01 * (5.0 - 400.0)]
    expected = torch.tensor([10.0 * (2 / (1 + math.exp(-s)) - 1) for s in drive])
    torch.testing.assert_close(weighted_rate_force(rates, w, sigma), expected)
    big = weighted_rate_force(torch.tensor([[1e4]]), torch.tensor([1.0]), 1.0, f_max=10.0)
    assert -10.0 <= big.item() <= 10.0


def test_bang_bang_force():
    # strictly above the threshold pushes positive; exactly at it, negative (one rule everywhere)
    torch.testing.assert_close(bang_bang_force(torch.tensor([10.0, 50.0, 49.9, 50.1]), threshold=50.0),
                               torch.tensor([-10.0, -10.0, -10.0, 10.0]))


def test_every_bang_bang_decoder_applies_one_threshold_rule():
    """The functional decoder, the module, the sigmoid controller (output > 0.5) and the C kernels
    agree at the threshold itself."""
    from evolution import NEAT, NEATConfig, SigmoidSpec, make_controller
    from snn_torch.modules.coding import BangBang

    drive = torch.tensor([-1.0, 0.0, 1e-7, 2.0], dtype=torch.float64)
    expected = torch.tensor([-3.0, -3.0, 3.0, 3.0], dtype=torch.float64)
    assert torch.equal(bang_bang_force(drive, f_max=3.0), expected)
    assert torch.equal(BangBang(3.0)(drive), expected)

    class Still:  # a plant whose observations put the sigmoid output exactly at 0.5
        observation_size, action_size, action_max = 1, 1, 3.0

    cfg = NEATConfig(num_inputs=1, num_outputs=1, num_bias=0, pop_size=2, max_hidden=0, sigma_mutate_rate=0.0,
                     compatibility_sigma_coefficient=0.0)
    genomes = NEAT(cfg).ask()
    genomes.weight.zero_()  # output = sigmoid(0) = 0.5 exactly
    controller = make_controller(genomes, cfg, Still(), SigmoidSpec(decoder="bang_bang"))
    action, _, _ = controller.act(torch.zeros(2, 1), controller.initial_state(torch.arange(2)))
    assert action.flatten().tolist() == [-3.0, -3.0]
