"""`snn-neat reproduce`: end to end, resumable after a real SIGKILL, clear errors."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from evolution.checkpoint import load_checkpoint_dict
from tasks.studies.cli import main
from tasks.studies.reproduce import ReproduceError, run_controller, write_report
from tasks.studies.results import ControllerRuns, mann_whitney

ROOT = Path(__file__).resolve().parents[2]


def _rows(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def test_short_reproduction_writes_every_artefact(tmp_path, capsys):
    out = tmp_path / "t2"
    assert main(["reproduce", "table2", "--runs", "2", "--generations", "3", "--seed", "100",
                 "--out", str(out), "--quiet", "--threads", "1"]) == 0
    names = {p.name for p in out.iterdir()}
    for name in ("table2.md", "table2.csv", "runs.csv", "summary.json", "fig8_best_fitness.png",
                 "trajectory_snn.png", "trajectory_sigmoid.png", "topology_snn.png", "topology_sigmoid.png",
                 "snn.ckpt", "sigmoid.ckpt", "champions"):
        assert name in names, name
    for png in out.glob("*.png"):
        assert png.stat().st_size > 10_000
    assert len(list((out / "champions").glob("*.json"))) == 4
    runs = _rows(out / "runs.csv")
    assert [(r["controller"], r["seed"]) for r in runs] == [("snn", "100"), ("snn", "101"),
                                                              ("sigmoid", "100"), ("sigmoid", "101")]
    for r in runs:
        g = int(r["solved_generation"])
        assert int(r["counted_generations"]) == (g if g > 0 else 4)
        assert 0.0 <= float(r["generalization"]) <= 1.0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["rows"]) == {"snn", "sigmoid"}
    assert 0.0 <= summary["mann_whitney_u"]["p_value"] <= 1.0
    assert summary["paper"]["snn"]["median"] == 21.5
    table = (out / "table2.md").read_text()
    assert "| NEAT-SNN | paper | 5 | 65 | 21.5 | 24.70 | 0/60 |" in table and "Mann-Whitney" in table
    assert "table2.md" in capsys.readouterr().out
    # Without --resume, an existing reproduction is not overwritten.
    with pytest.raises(SystemExit, match="--resume"):
        main(["reproduce", "table2", "--runs", "2", "--generations", "3", "--seed", "100", "--out", str(out),
              "--quiet"])


def test_short_markov_reproduction_writes_trajectories(tmp_path):
    out = tmp_path / "t1"
    assert main(["reproduce", "table1", "--runs", "2", "--generations", "2", "--seed", "100",
                 "--out", str(out), "--quiet", "--threads", "1"]) == 0
    for name in ("table1.md", "fig8_best_fitness.png", "trajectory_snn.png", "trajectory_sigmoid.png",
                 "topology_snn.png", "topology_sigmoid.png"):
        assert (out / name).stat().st_size > (10_000 if name.endswith(".png") else 100), name
    assert "| NEAT-SNN | paper | 1 | 92 | 9.5 | 16.55 | 1/60 |" in (out / "table1.md").read_text()


def test_resume_rejects_a_different_reproduction(tmp_path):
    run_controller("table2", "sigmoid", [0, 1], 2, tmp_path, progress=False)
    with pytest.raises(ReproduceError, match="seeds"):
        run_controller("table2", "sigmoid", [0, 2], 2, tmp_path, resume=True, progress=False)
    with pytest.raises(ReproduceError, match="table must be one of"):
        run_controller("table3", "sigmoid", [0], 2, tmp_path, progress=False)


def test_interrupted_then_resumed_equals_uninterrupted(tmp_path):
    kw = dict(generations=6, progress=False)
    whole = run_controller("table2", "snn", [5, 6, 7], out=tmp_path / "a", **kw)
    part = run_controller("table2", "snn", [5, 6, 7], out=tmp_path / "b", stop_after=2, **kw)
    assert not part.extra["complete"]
    done = run_controller("table2", "snn", [5, 6, 7], out=tmp_path / "b", resume=True, **kw)
    assert done.solved_generation == whole.solved_generation and done.best_fitness == whole.best_fitness
    assert torch.equal(done.history, whole.history)
    for name, t in whole.champions.tensors().items():
        assert torch.equal(getattr(done.champions, name), t)


def test_a_reproduction_resumed_with_another_budget_equals_the_run_that_had_it(tmp_path):
    seeds = [5, 6, 7]
    whole = run_controller("table2", "sigmoid", seeds, 16, tmp_path / "a", progress=False)
    short = run_controller("table2", "sigmoid", seeds, 8, tmp_path / "b", progress=False)
    assert short.extra["complete"] and short.solved_generation == [-1, -1, -1] != whole.solved_generation
    longer = run_controller("table2", "sigmoid", seeds, 16, tmp_path / "b", resume=True, progress=False)
    assert longer.generations == 16 and longer.solved_generation == whole.solved_generation
    assert torch.equal(longer.history, whole.history) and longer.best_fitness == whole.best_fitness
    for name, t in whole.champions.tensors().items():
        assert torch.equal(getattr(longer.champions, name), t)
    with pytest.raises(ReproduceError, match="written with generations=16, this call asks for generations=12"):
        run_controller("table2", "sigmoid", seeds, 12, tmp_path / "b", resume=True, progress=False)  # past it
    # stopped early, a run may be given a smaller budget it has not reached yet
    part = run_controller("table2", "sigmoid", seeds, 16, tmp_path / "c", progress=False, stop_after=4)
    assert not part.extra["complete"]
    cut = run_controller("table2", "sigmoid", seeds, 8, tmp_path / "c", resume=True, progress=False)
    assert cut.generations == 8 and torch.equal(cut.history, short.history) and cut.best_fitness == short.best_fitness


def test_sigkill_midway_then_resume_gives_the_same_table(tmp_path):
    args = ["reproduce", "table2", "--runs", "3", "--generations", "12", "--seed", "40", "--quiet", "--threads", "1",
            "--no-generalization"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    ref, cut = tmp_path / "ref", tmp_path / "cut"
    subprocess.run([sys.executable, "-m", "tasks.studies.cli", *args, "--out", str(ref)], check=True, env=env,
                   capture_output=True, timeout=600)
    proc = subprocess.Popen([sys.executable, "-m", "tasks.studies.cli", *args, "--out", str(cut)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = cut / "snn.ckpt"
    deadline = time.time() + 300
    while time.time() < deadline:
        if ckpt.exists() and load_checkpoint_dict(ckpt)["neat"]["generation"] >= 2:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the reproduction finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (cut / "table2.md").exists()
    subprocess.run([sys.executable, "-m", "tasks.studies.cli", *args, "--out", str(cut), "--resume"], check=True, env=env,
                   capture_output=True, timeout=600)
    assert _rows(cut / "runs.csv") == _rows(ref / "runs.csv")
    strip = lambda rows: [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]  # noqa: E731
    assert strip(_rows(cut / "table2.csv")) == strip(_rows(ref / "table2.csv"))


def test_mann_whitney_and_counting():
    assert mann_whitney([5] * 10, [5] * 10)["p_value"] == 1.0
    assert mann_whitney(list(range(1, 11)), list(range(50, 60)))["p_value"] < 0.001
    r = ControllerRuns("snn", [0, 1, 2], 100, [5, -1, 30], [5000.0, 10.0, 5000.0], torch.zeros(0, 3), None, None, 0.0)
    assert r.counted() == [5, 101, 30]
    row = r.row()
    assert (row["best"], row["worst"], row["median"], row["failure_rate"]) == (5, 101, 30, "1/3")


def test_sensitivity_sweep_rows_and_cli(capsys):
    from experiments.sensitivity import main as sensitivity_main
    from experiments.sensitivity import sweep

    rows = sweep("table2", "weight_mutate_power", [0.5, 2.5], [0, 1, 2], generations=3)
    assert [(r["value"], r["controller"]) for r in rows] == [(0.5, "snn"), (0.5, "sigmoid"), (2.5, "snn"),
                                                               (2.5, "sigmoid")]
    for r in rows:
        assert r["runs"] == 3 and 0 <= r["failures"] <= 3 and 1 <= r["median"] <= 4
    assert 0.0 <= rows[1]["p_value"] <= 1.0 and "p_value" not in rows[0]
    sensitivity_main(["table2", "--param", "weight_mutate_power", "--values", "1", "--seeds", "0-1",
                      "--generations", "2", "--controllers", "sigmoid"])
    out = capsys.readouterr().out
    assert "weight_mutate_power in [1.0]" in out and "sigmoid" in out


def test_ga_choice_reaches_the_config_and_guards_resume(tmp_path):
    from experiments.sensitivity import parse_value
    from tasks.studies.registry import GA_CHOICES, STUDIES

    python_like = run_controller("table1", "sigmoid", [0, 1], 1, tmp_path / "np", ga="neat-python", progress=False)
    cfg = python_like.config
    assert cfg.weight_mutate_per_gene and cfg.elitism == 2 and cfg.weight_mutate_power == 0.5
    assert python_like.row()["ga"] == "neat-python"
    tuned = run_controller("table1", "sigmoid", [0, 1], 1, tmp_path / "tuned", progress=False)
    preset, extra = STUDIES["table1"].tuned_ga["sigmoid"]
    for key, value in extra.items():
        assert getattr(tuned.config, key) == value
    assert tuned.row()["ga"].startswith(preset)
    assert STUDIES["table2"].ga_choice("snn", "neat-c++") == ("neat-c++", {})
    with pytest.raises(ReproduceError, match="cannot resume .* ga="):
        run_controller("table1", "sigmoid", [0, 1], 1, tmp_path / "np", resume=True, ga="neat-c++", progress=False)
    with pytest.raises(ReproduceError, match="ga must be one of"):
        run_controller("table1", "sigmoid", [0], 1, tmp_path / "bad", ga="neat-java", progress=False)
    from tasks.studies.cli import build_parser

    reproduce = build_parser()._subparsers._group_actions[0].choices["reproduce"]
    choices = {a.dest: a.choices for a in reproduce._actions if a.choices}
    assert list(choices["table"]) == list(STUDIES) and list(choices["ga"]) == list(GA_CHOICES)  # from the registry
    assert parse_value("2", "elitism") == 2 and parse_value("1", "weight_mutate_power") == 1.0
    assert parse_value("true", "weight_mutate_per_gene") is True
    with pytest.raises(ValueError, match="NEATConfig.elitism"):
        parse_value("2.5", "elitism")


def test_tune_ga_tries_every_preset_and_threshold_and_picks_the_lowest_mean(capsys):
    from experiments.tune_ga import main as tune_main
    from experiments.tune_ga import tune

    seen = []
    rows, best = tune("table2", "sigmoid", [0, 1], survival=[0.1, 0.2], generations=2, report=seen.append)
    assert [(r["ga"], r["value"]) for r in rows] == [("neat-c++", 0.1), ("neat-c++", 0.2), ("neat-python", 0.1),
                                                       ("neat-python", 0.2)]
    assert seen == rows and best["mean"] == min(r["mean"] for r in rows)
    tune_main(["table2", "--controllers", "sigmoid", "--seeds", "0-1", "--generations", "2", "--survival", "0.2"])
    assert "picked:" in capsys.readouterr().out


def test_results_do_not_depend_on_a_c_compiler(tmp_path):
    """The same short reproduction with every C kernel (whole episodes natively), with the C
    kernels but the Python loop over control steps, and with no C at all (no compiler, an empty
    cache): byte-identical runs.csv."""
    outputs = []
    for name, env in (("kernels", {}), ("python loop", {"SNN_NEAT_NATIVE_EPISODES": "0"}),
                      ("no compiler", {"CC": str(tmp_path / "no-such-cc"), "PATH": "/nonexistent",
                                       "SNN_NEAT_CACHE": str(tmp_path / "empty-cache")})):
        out = tmp_path / name.replace(" ", "_")
        proc = subprocess.run([sys.executable, "-m", "tasks.studies.cli", "reproduce", "table2", "--runs", "2",
                               "--generations", "3", "--seed", "100", "--out", str(out), "--quiet", "--threads", "1"],
                              cwd=ROOT, env={**os.environ, **env}, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr
        outputs.append((out / "runs.csv").read_bytes())
        if name == "no compiler":
            assert "torch path" in proc.stderr  # the fallback says so
    assert outputs[0] == outputs[1] == outputs[2]


def test_the_tables_signed_coding_is_a_sensitivity_study_of_the_same_runs(tmp_path):
    """`--coding signed` on the paper's tables: the paper's specs with signed inputs (push-pull
    pairs for Table I's Bernoulli encoder, so twice the input nodes), recorded in the report."""
    from tasks.studies.cartpole import markov_config, paper_spec
    from tasks.studies.reproduce import study_config

    assert paper_spec("table2", "snn", "signed").input_coding == "signed"
    assert paper_spec("table1", "snn", "signed").input_coding == "push_pull"
    assert paper_spec("table1", "sigmoid", "signed").input_coding == "signed"
    assert paper_spec("table2", "snn") == paper_spec("table2", "snn", "study")
    assert markov_config("snn", coding="signed").num_inputs == 8 and markov_config("sigmoid", coding="signed").num_inputs == 4
    assert study_config("table1", "snn", coding="signed").num_inputs == 8
    signed = run_controller("table2", "sigmoid", [0, 1], 3, tmp_path / "signed", progress=False, coding="signed")
    paper = run_controller("table2", "sigmoid", [0, 1], 3, tmp_path / "paper", progress=False)
    assert signed.extra["coding"] == "signed" and not torch.equal(signed.history, paper.history)
    write_report({"sigmoid": signed}, "table2", tmp_path / "signed", command="test", generalization=True)
    from tasks.studies.generalization import success_rate

    expected = success_rate(signed.champions, signed.config, controller="sigmoid",
                            spec=paper_spec("table2", "sigmoid", "signed"))[:, 0].tolist()
    unit = success_rate(signed.champions, signed.config, controller="sigmoid")[:, 0].tolist()
    assert signed.extra["generalization"] == expected != unit  # the champions tested with their own coding
    assert "Input coding: signed (`--coding signed`, a sensitivity study" in (tmp_path / "signed" / "table2.md").read_text()
    with pytest.raises(ReproduceError, match="cannot resume .* coding='signed', this call asks for coding='study'"):
        run_controller("table2", "sigmoid", [0, 1], 3, tmp_path / "signed", progress=False, resume=True)


def test_dpv_default_setup_restarts_a_stagnant_population_and_dpnv_first_setup_does_not():
    # DPV's tuned GA carries NEAT 2002's whole-population stagnation (delta coding after 20
    # generations without a better genome); the other studies' tuned GAs keep theirs
    from tasks.studies.registry import STUDIES

    for controller in ("snn", "sigmoid"):
        assert STUDIES["dpv"].config(controller).population_stagnation == 20
        assert STUDIES["dpv"].config(controller, setup="neat-1.2.1").population_stagnation == 20  # its own file's
        assert STUDIES["dpnv"].config(controller, setup="neat-2002").population_stagnation == 0
        assert STUDIES["table2"].config(controller).population_stagnation == 0
