"""The glibc malloc tuning: applied once, and not at all when switched off."""

import snn_torch._malloc as malloc_module


def test_keep_freed_memory_applies_once_and_respects_the_switch(monkeypatch):
    monkeypatch.setattr(malloc_module, "_done", False)
    monkeypatch.setenv("SNN_NEAT_MALLOC", "0")
    assert malloc_module.keep_freed_memory() is False
    assert malloc_module._done is False  # switched off: nothing recorded, nothing applied
    monkeypatch.delenv("SNN_NEAT_MALLOC")
    first = malloc_module.keep_freed_memory()
    assert isinstance(first, bool) and malloc_module._done
    assert malloc_module.keep_freed_memory() is False  # once per process
