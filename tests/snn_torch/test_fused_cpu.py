"""The fused C substep kernel against the torch reference step."""

import shutil

import pytest
import torch

from snn_torch.functional.fused_cpu import fused_available, fused_recurrent_izhikevich_steps, supports
from snn_torch.functional.izhikevich import QIU2019, REGULAR_SPIKING
from snn_torch.functional.recurrent import recurrent_init, recurrent_izhikevich_step

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler on this machine: the torch step is used instead")


def _network(B, N, dtype, seed=0):
    g = torch.Generator().manual_seed(seed)
    mask = torch.rand(B, N, N, generator=g) < 0.4
    w = (torch.randn(B, N, N, generator=g) * 16 * mask).to(dtype)
    i = (5 + 60 * torch.rand(B, N, generator=g)).to(dtype)
    return w, i


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("p", [QIU2019, REGULAR_SPIKING])
def test_bitwise_equal_to_reference_step(dtype, p):
    assert fused_available()
    B, N = 64, 7
    w, i = _network(B, N, dtype)
    ref = fused = recurrent_init((B, N), p, dtype=dtype)
    total = 0
    for _ in range(40):  # 40 control steps of 20 substeps: spike timing errors would compound
        counts_ref = torch.zeros_like(i)
        for _ in range(20):
            z, ref = recurrent_izhikevich_step(i, ref, w, p, dt_ms=0.5, validate=False)
            counts_ref += z
        counts, fused = fused_recurrent_izhikevich_steps(i, fused, w, p, dt_ms=0.5, substeps=20)
        assert torch.equal(counts, counts_ref)
        total += int(counts.sum())
    for a, b in zip(ref, fused, strict=True):
        assert torch.equal(a, b)
    assert total > 1000  # the networks really spiked


def test_row_does_not_depend_on_batch_or_threads():
    w, i = _network(33, 9, torch.float32, seed=3)
    state = recurrent_init((33, 9), QIU2019)
    counts, new = fused_recurrent_izhikevich_steps(i, state, w, QIU2019, dt_ms=0.5, substeps=50)
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = recurrent_init((1, 9), QIU2019)
        c5, n5 = fused_recurrent_izhikevich_steps(i[5:6], one, w[5:6], QIU2019, dt_ms=0.5, substeps=50)
    finally:
        torch.set_num_threads(threads)
    assert torch.equal(c5[0], counts[5]) and torch.equal(n5.v[0], new.v[5])


def test_input_state_is_not_modified_and_bad_shapes_raise():
    w, i = _network(4, 5, torch.float32)
    state = recurrent_init((4, 5), QIU2019)
    before = [t.clone() for t in state]
    fused_recurrent_izhikevich_steps(i, state, w, QIU2019, dt_ms=0.5, substeps=10)
    assert all(torch.equal(a, b) for a, b in zip(before, state, strict=True))
    with pytest.raises(ValueError, match="w_eff"):
        fused_recurrent_izhikevich_steps(i, state, w[:, :4], QIU2019, dt_ms=0.5, substeps=10)
    assert not supports(recurrent_init((4, 5), QIU2019, dtype=torch.float16), w, QIU2019)
