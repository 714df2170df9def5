import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread

from tasks.cli import main


def test_figures_command_writes_both_pngs(tmp_path):
    assert main(["figures", "--out", str(tmp_path), "--dt-ms", "0.1"]) == 0
    for name in ("fig1_voltage_response.png", "fig2_fi_curve.png"):
        path = tmp_path / name
        img = imread(path)
        assert img.shape[0] > 300 and img.shape[1] > 400
        assert np.std(img[..., :3]) > 0.05  # something is drawn, not a blank canvas
    assert not list(tmp_path.glob(".*"))  # no temp files left behind


def test_bad_option_is_named(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["figures", "--dt-ms", "-1"])
    assert exc.value.code == 2
    assert "--dt-ms" in capsys.readouterr().err


def test_console_script_help():
    out = subprocess.run([sys.executable, "-m", "tasks.cli", "figures", "--help"],
                         capture_output=True, text=True, check=True).stdout
    assert "Fig. 1" in out and "--out" in out
