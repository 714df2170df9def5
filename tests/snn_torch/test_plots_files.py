"""snn_torch.plots writes figures atomically with an ordinary file's mode."""

import os
import stat

from matplotlib.figure import Figure

from snn_torch.plots import save_figure


def test_saved_figures_get_the_umask_mode_not_mkstemps(tmp_path):
    old = os.umask(0o022)
    try:
        path = save_figure(Figure(figsize=(1, 1)), tmp_path / "f.png")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644  # mkstemp alone would leave 0o600
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]  # no temp file left
