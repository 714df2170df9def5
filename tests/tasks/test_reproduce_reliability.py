"""`snn-neat reproduce` at the edges: a budget too large to pad, a report cut short."""

import os
import stat

import pytest
import torch

import tasks.studies.results as results
from evolution.checkpoint import CheckpointError, atomic_torch_save, load_checkpoint_dict
from tasks.studies.reproduce import FIG8_MAX_PAD, run_controller, write_report


def test_a_huge_budget_pads_fig8_to_a_bound_and_an_interrupted_report_does_not_look_complete(tmp_path, monkeypatch):
    # Before: padding Fig. 8's history to 10**12 generations crashed after evolution, and on
    # every --resume.
    kw = dict(generations=10**12, progress=False, stop_after=1)
    first = run_controller("table2", "sigmoid", [0], out=tmp_path, **kw)
    assert tuple(first.history.shape) == (FIG8_MAX_PAD, 1)
    good = load_checkpoint_dict(tmp_path / "sigmoid.ckpt")
    for key, value, match in (("history", torch.zeros(3, 1, dtype=torch.float64), r"history should be \(1, 1\)"),
                              ("neat", None, "holds no NEAT state"), ("wall_s", "x", "wall_s is 'x'")):
        atomic_torch_save({**good, key: value}, tmp_path / "crafted" / "sigmoid.ckpt")
        with pytest.raises(CheckpointError, match=f"crafted/sigmoid.ckpt.*{match}"):
            run_controller("table2", "sigmoid", [0], out=tmp_path / "crafted", resume=True, **kw)
    r = run_controller("table2", "sigmoid", [0], out=tmp_path, resume=True, **kw)
    assert tuple(r.history.shape) == (FIG8_MAX_PAD, 1) and not r.extra["complete"]
    assert (r.history[1:] == r.history[1]).all() and r.history[0] <= r.history[1]

    old = os.umask(0o022)
    try:
        written = write_report({"sigmoid": r}, "table2", tmp_path, command="test", generalization=False)
    finally:
        os.umask(old)
    assert [p.name for p in written[-2:]] == ["summary.json", "table2.md"]  # written last
    for name in ("fig8_best_fitness.png", "topology_sigmoid.png", "runs.csv", "table2.md"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644, name  # the umask's mode, not 0600

    def full_disk(fig, path):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(results, "save_png", full_disk)
    with pytest.raises(OSError):
        write_report({"sigmoid": r}, "table2", tmp_path, command="test", generalization=False)
    assert not (tmp_path / "table2.md").exists() and not (tmp_path / "summary.json").exists()
