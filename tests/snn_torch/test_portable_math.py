"""snn_torch.functional.portable_math: accurate, and the C twin (portable_math.h) gives the same bits."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from snn_torch.functional import portable_math as pm
from snn_torch.kernels.build import load_library

_PROBE = Path(__file__).resolve().parent.parent / "csrc"


def _ulps(got: torch.Tensor, want: np.ndarray) -> np.ndarray:
    g = got.numpy()
    return np.abs(g - want) / np.spacing(np.abs(want))


def _samples(n: int, scale: float, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = (torch.rand(n, generator=g, dtype=torch.float64) - 0.5) * 2 * scale
    special = torch.tensor([0.0, -0.0, 1e-300, math.pi / 4, math.pi / 2, math.pi, -math.pi, 3 * math.pi / 4,
                            1e5, -1e5], dtype=torch.float64)
    return torch.cat([x, special])


@pytest.mark.parametrize("scale", [1.0, 7.0, 1e5])
def test_sin_cos_within_two_ulp(scale):
    x = _samples(20000, scale)
    s, c = pm.sin_cos(x)
    want_s = np.array([math.sin(v) for v in x.tolist()])
    want_c = np.array([math.cos(v) for v in x.tolist()])
    # ulps relative to the result away from the function's zeros; near them the reduction's
    # absolute error (about |x| * 1e-32) is what counts, so compare absolutely as well
    big_s, big_c = np.abs(want_s) > 1e-3, np.abs(want_c) > 1e-3
    assert _ulps(s, want_s)[big_s].max() <= 2
    assert _ulps(c, want_c)[big_c].max() <= 2
    assert np.abs(s.numpy() - want_s).max() <= 4e-16 * max(1.0, scale)
    assert np.abs(c.numpy() - want_c).max() <= 4e-16 * max(1.0, scale)


def test_exp_within_two_ulp_and_clamped():
    x = _samples(20000, 700.0)
    x = x[x.abs() <= pm.EXP_CLAMP]
    want = np.array([math.exp(v) for v in x.tolist()])
    assert _ulps(pm.exp(x), want).max() <= 2
    big = pm.exp(torch.tensor([800.0, -800.0, math.inf, -math.inf], dtype=torch.float64))
    assert big.tolist() == pm.exp(torch.tensor([708.0, -708.0, 708.0, -708.0], dtype=torch.float64)).tolist()
    assert bool(torch.isfinite(big).all())


def test_nan_and_inf_give_nan():
    x = torch.tensor([math.nan, math.inf, -math.inf], dtype=torch.float64)
    s, c = pm.sin_cos(x)
    assert bool(torch.isnan(s).all()) and bool(torch.isnan(c).all())
    assert bool(torch.isnan(pm.exp(x[:1])).all()) and bool(torch.isnan(pm.sigmoid(x[:1])).all())


def test_float32_is_rounded_once_from_float64():
    x = _samples(5000, 10.0).to(torch.float32)
    s, c = pm.sin_cos(x)
    s64, c64 = pm.sin_cos(x.to(torch.float64))
    assert s.dtype == torch.float32 and torch.equal(s, s64.to(torch.float32)) and torch.equal(c, c64.to(torch.float32))
    y = pm.sigmoid(x)
    assert y.dtype == torch.float32 and torch.equal(y, pm.sigmoid(x.to(torch.float64)).to(torch.float32))
    assert float(pm.sigmoid(torch.tensor([0.0]))[0]) == 0.5


def test_batch_position_does_not_matter():
    x = _samples(3000, 20.0)[:3000]
    s, c = pm.sin_cos(x)
    one = [pm.sin_cos(x[i : i + 1]) for i in range(0, 3000, 97)]
    assert torch.equal(torch.cat([o[0] for o in one]), s[::97]) and torch.equal(torch.cat([o[1] for o in one]), c[::97])


@pytest.fixture(scope="module")
def probe():
    lib = load_library("portable_math_probe", _PROBE / "portable_math_probe.c", _PROBE / "portable_math_probe.h")
    if lib is None:
        pytest.skip("no C compiler (the torch path is the definition; nothing to compare)")
    return lib


def test_c_twin_gives_the_same_bits(probe):
    x = torch.cat([_samples(50000, 4.0, seed=1), _samples(50000, 1e4, seed=2),
                   torch.tensor([math.nan, math.inf, -math.inf], dtype=torch.float64)])
    s, c = torch.empty_like(x), torch.empty_like(x)
    probe.probe_sincos(x.data_ptr(), s.data_ptr(), c.data_ptr(), x.numel())
    ts, tc = pm.sin_cos(x)
    assert torch.equal(s[:-3], ts[:-3]) and torch.equal(c[:-3], tc[:-3])
    assert bool(torch.isnan(s[-3:]).all() and torch.isnan(ts[-3:]).all())
    e = _samples(100000, 750.0, seed=3)
    y = torch.empty_like(e)
    probe.probe_exp(e.data_ptr(), y.data_ptr(), e.numel())
    assert torch.equal(y, pm.exp(e))
    f = _samples(100000, 30.0, seed=4).to(torch.float32)
    yf = torch.empty_like(f)
    probe.probe_sigmoid_f32(f.data_ptr(), yf.data_ptr(), f.numel())
    assert torch.equal(yf, pm.sigmoid(f))
