"""The MKL VML warm-up runs at import, once, over ops that exist for both float dtypes."""

import torch

import snn_torch  # noqa: F401  (the import runs the warm-up)
from snn_torch import _vml_warmup


def test_import_warmed_up_vml_once_and_the_ops_exist():
    assert _vml_warmup._done  # ran when snn_torch was imported
    assert _vml_warmup.warm_up_vml() is False  # and only once
    for name in ("log", "exp", "sin", "cos", "sqrt", "tanh"):
        assert name in _vml_warmup.WARMED_OPS
    for dtype in (torch.float32, torch.float64):
        x = torch.full((3,), 0.5, dtype=dtype)
        for name in _vml_warmup.WARMED_OPS:
            assert getattr(torch, name)(x).dtype == dtype, name
