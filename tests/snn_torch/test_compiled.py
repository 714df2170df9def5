"""The compiled substep (torch.compile) against the eager reference step."""

import warnings

import pytest
import torch

import snn_torch.kernels.compiled as compiled_mod
from snn_torch.functional import QIU2019, IzhikevichParams, recurrent_init, recurrent_izhikevich_step
from snn_torch.kernels.compiled import CompiledSubstep


def _network(B, N, seed):
    g = torch.Generator().manual_seed(seed)
    w = torch.randn(B, N, N, generator=g) * 40.0 * (torch.rand(B, N, N, generator=g) < 0.4)
    i_ext = 5.0 + 10.0 * torch.rand(B, N, generator=g)
    return w, i_ext


def _run(step, i_ext, w, substeps, p):
    state, counts = recurrent_init(i_ext.shape, p, device=i_ext.device), torch.zeros_like(i_ext)
    for _ in range(substeps):
        state, counts = step(i_ext, state, w, counts)
    return state, counts


def _eager(p, dt_ms=0.5):
    def step(i_ext, state, w, counts):
        z, state = recurrent_izhikevich_step(i_ext, state, w, p, dt_ms=dt_ms)
        return state, counts + z
    return step


def test_compiled_substep_equals_the_eager_step_bit_for_bit():
    step = CompiledSubstep(QIU2019, dt_ms=0.5)
    for B in (64, 37):  # a second batch size: one graph serves both (dynamic shapes)
        w, i_ext = _network(B, 8, B)
        state, counts = _run(step, i_ext, w, 40, QIU2019)
        assert step.compiled, step.reason  # else this would compare the eager step with itself
        ref_state, ref_counts = _run(_eager(QIU2019), i_ext, w, 40, QIU2019)
        assert counts.sum() > 0 and (counts < counts.max()).any()  # spiking, and not uniformly
        assert torch.equal(counts, ref_counts)
        for got, want in zip(state, ref_state, strict=True):
            assert torch.equal(got, want)


def test_a_failing_compiler_falls_back_to_the_eager_step_once(monkeypatch):
    def broken(fn):
        def call(*args):
            raise RuntimeError("no compiler here\nsecond line")
        return call

    monkeypatch.setattr(compiled_mod, "_compile", broken)
    p = IzhikevichParams(0.02, 0.2, -65.0, 8.0, 30.0 - 1e-3)  # a key no other test compiled
    step = CompiledSubstep(p, dt_ms=0.5)
    assert step.compiled
    w, i_ext = _network(16, 6, 0)
    with pytest.warns(RuntimeWarning, match="torch.compile failed .*no compiler here"):
        state, counts = _run(step, i_ext, w, 20, p)
    assert not step.compiled and "RuntimeError" in step.reason
    ref_state, ref_counts = _run(_eager(p), i_ext, w, 20, p)
    assert torch.equal(counts, ref_counts) and torch.equal(state.v, ref_state.v)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a later step of the same key neither retries nor warns
        again = CompiledSubstep(p, dt_ms=0.5)
        assert not again.compiled and again.reason == step.reason
        _run(again, i_ext, w, 2, p)
    compiled_mod._compiled.pop(again._key)


def test_bad_input_raises_without_turning_compilation_off():
    step = CompiledSubstep(QIU2019, dt_ms=0.5)
    w, i_ext = _network(16, 8, 4)
    with pytest.raises(RuntimeError):
        _run(step, i_ext, w[:, :5, :5], 1, QIU2019)  # weights of 5 nodes for a state of 8
    assert step.compiled and step.reason is None
    state, counts = _run(step, i_ext, w, 5, QIU2019)
    assert step.compiled
    ref_state, ref_counts = _run(_eager(QIU2019), i_ext, w, 5, QIU2019)
    assert torch.equal(counts, ref_counts) and torch.equal(state.v, ref_state.v)


def test_a_compiler_refusing_at_once_falls_back_too(monkeypatch):
    def refuses(fn):
        raise RuntimeError("torch.compile is not supported on this Python")

    monkeypatch.setattr(compiled_mod, "_compile", refuses)
    p = IzhikevichParams(0.02, 0.2, -65.0, 8.0, 30.0 - 2e-3)  # a key no other test compiled
    with pytest.warns(RuntimeWarning, match="not supported on this Python"):
        step = CompiledSubstep(p, dt_ms=0.5)
    assert not step.compiled
    w, i_ext = _network(8, 5, 2)
    state, counts = _run(step, i_ext, w, 10, p)
    ref_state, ref_counts = _run(_eager(p), i_ext, w, 10, p)
    assert torch.equal(counts, ref_counts) and torch.equal(state.v, ref_state.v)
    compiled_mod._compiled.pop(step._key)


def test_tensor_parameters_run_eagerly_and_say_why():
    p = IzhikevichParams(torch.full((6,), 0.02), 0.2, -65.0, 8.0)
    step = CompiledSubstep(p, dt_ms=0.5)
    assert not step.compiled and "tensor" in step.reason
    w, i_ext = _network(8, 6, 1)
    state, counts = _run(step, i_ext, w, 10, p)
    ref_state, ref_counts = _run(_eager(p), i_ext, w, 10, p)
    assert torch.equal(counts, ref_counts) and torch.equal(state.u, ref_state.u)


@pytest.mark.parametrize("bad", [{"dt_ms": 0.0}, {"method": "rk4"}])
def test_bad_settings_are_refused_by_name(bad):
    with pytest.raises(ValueError, match="dt|method"):
        CompiledSubstep(QIU2019, **bad)


def test_compiled_substep_on_cuda_agrees_with_the_eager_step():
    # Triton may contract multiply-adds, so on CUDA one substep agrees to rounding, not bit for bit.
    w, i_ext = _network(4096, 8, 3)
    w, i_ext = w.cuda(), i_ext.cuda()
    step = CompiledSubstep(QIU2019, dt_ms=0.5)
    state, counts = _run(step, i_ext, w, 1, QIU2019)
    assert step.compiled, step.reason
    ref_state, ref_counts = _run(_eager(QIU2019), i_ext, w, 1, QIU2019)
    assert state.v.device.type == "cuda"
    assert torch.equal(counts, ref_counts)
    torch.testing.assert_close(state.v, ref_state.v, rtol=1e-5, atol=1e-4)
    torch.testing.assert_close(state.u, ref_state.u, rtol=1e-5, atol=1e-5)
