"""The C kernels' switch: ``SNN_NEAT_C_KERNELS=0``, and its old name ``SNN_NEAT_FUSED`` still read."""

import warnings

import pytest

from snn_torch.kernels import build as _cbuild

NAMES = ("SNN_NEAT_C_KERNELS", "SNN_NEAT_FUSED")


@pytest.mark.parametrize(("env", "enabled"), [
    ({}, True),
    ({"SNN_NEAT_C_KERNELS": "0"}, False),
    ({"SNN_NEAT_C_KERNELS": "1"}, True),
    ({"SNN_NEAT_C_KERNELS": "1", "SNN_NEAT_FUSED": "0"}, True),  # the new name wins
])
def test_the_switch_reads_the_new_name(monkeypatch, env, enabled):
    for name in NAMES:
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert _cbuild.kernels_enabled() is enabled


def test_the_old_name_still_switches_the_kernels_off_and_warns_once(monkeypatch):
    monkeypatch.delenv("SNN_NEAT_C_KERNELS", raising=False)
    monkeypatch.setenv("SNN_NEAT_FUSED", "0")
    monkeypatch.setattr(_cbuild, "_warned_old_switch", False)
    with pytest.warns(DeprecationWarning, match="SNN_NEAT_C_KERNELS"):
        assert not _cbuild.kernels_enabled()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not _cbuild.kernels_enabled()
