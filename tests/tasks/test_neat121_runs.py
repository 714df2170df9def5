"""NEAT C++ 1.2.1's per-run data (tasks/studies/neat121_runs.json) and the tests against it."""

from __future__ import annotations

import json
import statistics

import pytest

from tasks.studies import neat121_runs as module
from tasks.studies.double_pole import PUBLISHED
from tasks.studies.neat121_runs import compare_with_neat121, neat121_runs


@pytest.mark.parametrize(("variant", "population"), [("dpv", 150), ("dpnv", 1000)])
def test_the_data_holds_one_record_per_seed_and_the_report_row_is_computed_from_it(variant, population):
    runs = neat121_runs(variant)
    assert runs.population == population and len(runs.seeds) == len(set(runs.seeds)) >= 100
    solved = runs.solved_evaluations
    assert all(0 < e <= 100 * population for e in solved)  # within NEAT 1.2.1's 100 generations
    row = runs.row()
    assert row["neat121_mean"] == round(statistics.mean(solved)) and row["failures"] == f"{runs.failures}/{len(runs.seeds)}"
    assert row in PUBLISHED[variant]
    if variant == "dpnv":  # a DPNV solution holds at least 200 of the 625 starts
        assert all(g >= 200 for g in runs.generalization if g is not None)
        assert [g is None for g in runs.generalization] == [e is None for e in runs.evaluations]


def test_the_comparison_tells_the_same_distribution_from_a_slower_one():
    theirs = neat121_runs("dpnv")
    same = compare_with_neat121(list(theirs.evaluations), "dpnv")
    assert same["mann_whitney_p"] == pytest.approx(1.0) and same["fisher_p"] == pytest.approx(1.0)
    slower = compare_with_neat121([None if e is None else 2 * e for e in theirs.evaluations], "dpnv")
    assert slower["mann_whitney_p"] < 1e-6 and slower["median"] == 2 * same["median"]
    failing = compare_with_neat121([None] * 50 + [10_000] * 50, "dpnv")
    assert failing["failures"] == 50 and failing["fisher_p"] < 1e-6
    none_solved = compare_with_neat121([None] * 3, "dpnv")
    assert "mann_whitney_p" not in none_solved and none_solved["median"] is None


def test_a_malformed_data_file_is_refused_naming_the_field(tmp_path, monkeypatch):
    data = json.loads(module.DATA_FILE.read_text())
    data["dpnv"]["cpu_s"] = data["dpnv"]["cpu_s"][:-1]
    bad = tmp_path / "neat121_runs.json"
    bad.write_text(json.dumps(data))
    monkeypatch.setattr(module, "DATA_FILE", bad)
    module.neat121_runs.cache_clear()
    try:
        with pytest.raises(ValueError, match=r"dpnv\.cpu_s"):
            module.neat121_runs("dpnv")
        with pytest.raises(ValueError, match="no runs of 'xor'"):
            module.neat121_runs("xor")
    finally:
        module.neat121_runs.cache_clear()
