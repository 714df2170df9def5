"""The plants of ``benchmarks/unseen_plants.py``: valid tasks whose thresholds a hand-made law
reaches and doing nothing does not, runnable by ``snn-neat evolve`` with the defaults."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import unseen_plants  # noqa: E402
from unseen_plants import PLANTS, REFERENCES, policy_returns, zero_action  # noqa: E402

from evolution import NEAT, TaskFitness, task_config  # noqa: E402
from evolution.defaults import has_random_starts  # noqa: E402


@pytest.mark.parametrize("name", list(PLANTS))
def test_the_reference_reaches_the_threshold_and_no_control_does_not(name):
    task = PLANTS[name]().validate()
    assert has_random_starts(task)  # so the defaults give 16 fresh episodes per genome
    reference = policy_returns(task, REFERENCES[name])
    zero = policy_returns(task, lambda obs: zero_action(obs, task.action_size))
    assert float(reference.mean()) >= task.reward_threshold > float(zero.mean())
    assert torch.equal(reference, policy_returns(task, REFERENCES[name]))  # seeded starts


@pytest.mark.parametrize("name", list(PLANTS))
def test_both_controllers_run_on_the_plant_with_the_defaults(name):
    task = PLANTS[name]()
    for controller in ("sigmoid", "snn"):
        config = task_config(task, controller, pop_size=6)
        fitness = TaskFitness(task, config, controller, seed=0, episodes=2)
        scores = fitness(NEAT(config, seeds=[0]).ask())
        assert scores.shape == (1, 6) and bool(torch.isfinite(scores).all())


def test_the_benchmark_prints_a_row_per_plant_and_method(capsys):
    assert unseen_plants.main(["--plants", "DoubleIntegrator", "--methods", "sigmoid", "--seeds", "0",
                               "--generations", "2"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| DoubleIntegrator")]
    assert len(rows) == 1 and "| sigmoid |" in rows[0] and "/1 |" in rows[0]
