import pytest
import torch

DEVICES = ["cpu", "cuda"]  # cuda cases skip (see below) when no GPU is present


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "cuda" in item.nodeid and not torch.cuda.is_available():
            item.add_marker(pytest.mark.skip(reason="no CUDA device"))
