import os
import stat
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread

from tasks.studies.cli import main


def test_figures_command_writes_both_pngs(tmp_path):
    old = os.umask(0o027)
    try:
        assert main(["figures", "--out", str(tmp_path), "--dt-ms", "0.1"]) == 0
    finally:
        os.umask(old)
    for name in ("fig1_voltage_response.png", "fig2_fi_curve.png"):
        path = tmp_path / name
        assert stat.S_IMODE(path.stat().st_mode) == 0o640  # the umask's mode, not mkstemp's 0600
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
    out = subprocess.run([sys.executable, "-m", "tasks.studies.cli", "figures", "--help"],
                         capture_output=True, text=True, check=True).stdout
    assert "Fig. 1" in out and "--out" in out


@pytest.mark.parametrize("command", ["figures", "xor", "evolve"])
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "--out" in capsys.readouterr().out


def test_evolve_writes_statistics_and_a_loadable_champion(tmp_path):
    from evolution.genome_io import load_genome
    from tasks.studies.cartpole import controller_config

    assert main(["evolve", "--controller", "snn", "--generations", "2", "--out", str(tmp_path), "--verbose"]) == 0
    rows = (tmp_path / "statistics.csv").read_text().splitlines()
    assert len(rows) == 3 and rows[0].startswith("generation,run,best_fitness")
    champion = load_genome(tmp_path / "champion.json", controller_config("snn"))
    assert champion.conn.sum() >= 2


def test_evolve_markov_task(tmp_path, capsys):
    from evolution.genome_io import load_genome
    from tasks.studies.cartpole import markov_config

    assert main(["evolve", "--task", "markov", "--controller", "sigmoid", "--generations", "2", "--seed", "3",
                 "--out", str(tmp_path), "--verbose"]) == 0
    champion = load_genome(tmp_path / "champion.json", markov_config("sigmoid"))
    assert champion.num_nodes == markov_config("sigmoid").num_nodes
    assert bool(champion.conn[0, 0, :4, markov_config("sigmoid").first_output].all())  # all four inputs wired
    assert "sigmoid seed 3" in capsys.readouterr().out


@pytest.mark.parametrize("argv, match", [
    (["evolve", "--device", "nope"], "--device 'nope'"),
    (["evolve", "--generations", "0"], "--generations"),
    (["evolve", "--task", "pendulum"], "--task"),
    (["xor", "--runs", "-3"], "--runs"),
])
def test_bad_options_are_named(argv, match, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    text = str(exc.value.code) + capsys.readouterr().err
    assert match in text
