"""``python -m experiments.classic_control`` end to end on a tiny budget, and its option errors."""

from __future__ import annotations

import csv
import json

import pytest

pytest.importorskip("gymnasium")
pytest.importorskip("matplotlib")

from experiments.classic_control import CSV_FIELDS, ENVIRONMENTS, main  # noqa: E402

TINY = ["--envs", "CartPole-v1", "Pendulum-v1", "--seeds", "1", "--generations", "2", "--pop-size", "30",
        "--episodes", "2", "--validation-episodes", "3", "--test-episodes", "4", "--quiet"]


def test_tiny_study_writes_consistent_files(tmp_path):
    out = tmp_path / "cc"
    returned = main([*TINY, "--out", str(out)])
    for name in ("results.json", "runs.csv", "summary.md", "training.png", "test_returns.png"):
        assert (out / name).stat().st_size > 0, name
    results = json.loads((out / "results.json").read_text())
    assert results["summary"] == json.loads(json.dumps(returned["summary"]))
    runs = results["runs"]
    with open(out / "runs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == CSV_FIELDS
    assert [(r["env"], r["controller"], int(r["seed"])) for r in rows] == \
        [(r["env"], r["controller"], r["seed"]) for r in runs] == \
        [(e, c, 1) for e in ("CartPole-v1", "Pendulum-v1") for c in ("snn", "sigmoid")]
    for row, run in zip(rows, runs, strict=True):
        threshold = ENVIRONMENTS[run["env"]].threshold
        assert run["threshold"] == threshold
        for key in ("train_generation", "evaluations", "confirmed_generation", "generations_run"):
            assert int(row[key]) == run[key], key
        for key in ("wall_s", "test_mean", "test_worst", "best_training_fitness"):
            assert float(row[key]) == pytest.approx(run[key], abs=1e-3), key
        assert row["test_reaches"] == str(run["test_reaches"])
        history = run["history"]
        assert 1 <= run["generations_run"] == len(history) <= 2
        assert run["best_training_fitness"] == max(history)
        assert run["test_worst"] <= run["test_mean"]
        assert run["test_reaches"] == (run["test_mean"] >= threshold)
        gen = run["train_generation"]
        if gen > 0:  # the first generation whose best training fitness reached the threshold
            assert history[gen - 1] >= threshold
            assert all(h < threshold for h in history[:gen - 1])
            assert run["evaluations"] == gen * 30 * 2
        else:
            assert all(h < threshold for h in history)
            assert run["evaluations"] == run["total_evaluations"] == len(history) * 30 * 2
        if run["confirmed_generation"] > 0:  # confirmed runs stop there
            assert gen <= run["confirmed_generation"] == run["generations_run"]
    assert any(r["train_generation"] > 0 for r in runs)  # (CartPole-v1's runs, seed 1)
    for s in results["summary"]:
        mine = [r for r in runs if (r["env"], r["controller"]) == (s["env"], s["controller"])]
        assert s["runs"] == len(mine)
        assert s["train_reached"] == sum(r["train_generation"] > 0 for r in mine)
        assert s["test_reached"] == sum(r["test_reaches"] for r in mine)
    assert "Pendulum-v1" in (out / "summary.md").read_text()


@pytest.mark.parametrize("argv, message", [
    (["--envs", "LunarLander-v3"], "invalid choice: 'LunarLander-v3'"),
    (["--controllers", "lstm"], "invalid choice: 'lstm'"),
    (["--seeds", "-1"], "must be a non-negative integer"),
    (["--seeds", "1", "1"], "--seeds repeats a value"),
    (["--generations", "0"], "must be a positive integer"),
    (["--pop-size", "1"], "--pop-size must be at least 2"),
    (["--test-episodes", "many"], "must be a positive integer, got 'many'"),
])
def test_bad_options_exit_with_a_clear_message(argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "never")])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "never").exists()
