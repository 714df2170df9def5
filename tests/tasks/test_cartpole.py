import math

import pytest
import torch

from tasks.cartpole import CartPoleParams, PlantError, cartpole_failed, cartpole_step, check_state


def reference_step(s, f, tau, g=9.8, mc=1.0, mp=0.1, l=0.5):  # noqa: E741
    """Qiu et al. eqs. (6)-(8), one state at a time, in Python floats (float64)."""
    x, xd, th, thd = s
    thdd = (g * math.sin(th) + math.cos(th) * ((-f - mp * l * thd**2 * math.sin(th)) / (mc + mp))) / (
        l * (4.0 / 3.0 - mp * math.cos(th) ** 2 / (mc + mp)))
    xdd = (f + mp * l * (thd**2 * math.sin(th) - thdd * math.cos(th))) / (mc + mp)
    return [x + tau * xd, xd + tau * xdd, th + tau * thd, thd + tau * thdd]


@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-12), (torch.float32, 1e-4)])
def test_batched_plant_matches_a_float64_loop(dtype, tol):
    g = torch.Generator().manual_seed(0)
    B = 16
    state = (torch.rand(B, 4, generator=g, dtype=torch.float64) - 0.5) * torch.tensor([1.0, 1.0, 0.2, 1.0],
                                                                                      dtype=torch.float64)
    forces = (torch.rand(200, B, generator=g, dtype=torch.float64) * 20 - 10)
    ref = state.tolist()
    s = state.to(dtype).reshape(4, 4, 4)  # any batch shape
    for t in range(200):
        s = cartpole_step(s, forces[t].to(dtype).reshape(4, 4), 0.01)
        ref = [reference_step(r, forces[t, b].item(), 0.01) for b, r in enumerate(ref)]
    torch.testing.assert_close(s.reshape(B, 4).double(), torch.tensor(ref, dtype=torch.float64), atol=tol, rtol=tol)
    assert s.dtype == dtype


def test_failure_limits():
    p = CartPoleParams()
    s = torch.tensor([[0.0, 0, 0, 0], [2.41, 0, 0, 0], [-2.39, 0, 0, 0], [0, 0, math.radians(12.1), 0],
                      [0, 0, -math.radians(11.9), 0]])
    assert cartpole_failed(s, p).tolist() == [False, True, False, True, False]


def test_pole_falls_without_control_and_force_pushes_the_cart():
    s = torch.tensor([[0.0, 0.0, math.radians(3), 0.0]], dtype=torch.float64)
    for _ in range(100):
        s = cartpole_step(s, torch.zeros(1, dtype=torch.float64), 0.01)
    assert s[0, 2] > math.radians(12)  # falls past the limit within 1 s
    s = cartpole_step(torch.zeros(1, 4), torch.tensor([10.0]), 0.02)
    s = cartpole_step(s, torch.tensor([10.0]), 0.02)
    assert s[0, 0] > 0 and s[0, 1] > 0 and s[0, 3] < 0  # pushing right tilts the pole left


def test_nan_state_is_reported_with_indices():
    s = torch.zeros(3, 5, 4)
    s[1, 2, 0] = float("nan")
    s[2, 4, 3] = float("inf")
    with pytest.raises(PlantError, match=r"\[1, 2\].*\[2, 4\]|2 batch"):
        check_state(s)
    with pytest.raises(ValueError, match="pole_mass"):
        CartPoleParams(pole_mass=-1.0)
