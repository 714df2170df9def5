import pytest
import torch

from snn_torch.functional.threshold import (
    fast_sigmoid,
    fast_sigmoid_primitive,
    heaviside,
    superspike,
    triangle,
    triangle_primitive,
)


def test_forward_is_a_step_at_zero():
    x = torch.tensor([-1.0, -1e-6, 0.0, 1e-6, 5.0])
    expected = torch.tensor([0.0, 0.0, 1.0, 1.0, 1.0])
    for fn in (heaviside, fast_sigmoid(), triangle()):
        assert torch.equal(fn(x), expected)


@pytest.mark.parametrize("slope", [0.5, 5.0, 25.0])
def test_fast_sigmoid_primitive_passes_gradcheck(slope):
    x = (torch.randn(20, dtype=torch.float64) * 3).requires_grad_()
    x = x + 0.01 * (x.detach() == 0)  # |x| is not differentiable at exactly 0
    assert torch.autograd.gradcheck(lambda t: fast_sigmoid_primitive(t, slope), (x,))


def test_triangle_primitive_passes_gradcheck():
    # Avoid the kinks at 0 and +-width where finite differences straddle the corner.
    x = torch.tensor([-20.0, -7.5, -3.0, -0.5, 0.4, 2.0, 8.5, 15.0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: triangle_primitive(t, 10.0), (x,))


@pytest.mark.parametrize(
    "spike_fn, primitive",
    [(fast_sigmoid(5.0), lambda t: fast_sigmoid_primitive(t, 5.0)),
     (superspike(25.0), lambda t: fast_sigmoid_primitive(t, 25.0)),
     (triangle(10.0), lambda t: triangle_primitive(t, 10.0))],
)
def test_surrogate_backward_is_the_primitive_derivative(spike_fn, primitive):
    x = torch.linspace(-30, 30, 241, dtype=torch.float64)
    x = x[x != 0]
    a = x.clone().requires_grad_()
    spike_fn(a).sum().backward()
    b = x.clone().requires_grad_()
    primitive(b).sum().backward()
    torch.testing.assert_close(a.grad, b.grad)


@pytest.mark.parametrize("spike_fn", [fast_sigmoid(), triangle()])
def test_surrogate_gradient_is_finite_and_nonzero_near_threshold(spike_fn):
    x = torch.linspace(-2.0, 2.0, 41, requires_grad=True)  # mV around v_peak
    spike_fn(x).sum().backward()
    assert bool(torch.isfinite(x.grad).all())
    assert bool((x.grad > 0).all())
    assert x.grad[20] == x.grad.max()  # steepest at the threshold


def test_heaviside_has_no_gradient_path():
    x = torch.randn(5, requires_grad=True)
    assert not heaviside(x).requires_grad


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_surrogate_parameters_are_rejected(bad):
    with pytest.raises(ValueError, match="slope"):
        fast_sigmoid(bad)
    with pytest.raises(ValueError, match="width"):
        triangle(bad)
