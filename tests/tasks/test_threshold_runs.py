"""The held-out check of ``tasks.studies.threshold_runs``: a genome passes only with a margin of
``CONFIDENCE_Z`` standard errors above the threshold, so a champion confirmed at the threshold is
not a coin flip on the test."""

import math

import pytest
import torch

from evolution import NEAT, TaskFitness, task_config
from evolution.task import Task
from tasks.studies.threshold_runs import CONFIDENCE_Z, ThresholdRuns, held_out_lower_bound


class CoinTask(Task):
    """One step whose reward is the start value, uniform in [0, 1): every controller scores the
    same, a mean of 0.5 with a standard deviation of 1/sqrt(12) per episode."""

    name = "coin"
    observation_low, observation_high = (0.0,), (1.0,)
    action_size, action_max, max_steps = 1, 1.0, 1

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        return torch.rand(batch, 1, generator=generator, dtype=torch.float64).to(device=device, dtype=dtype)

    def step(self, state, action):
        return state, state[:, 0].to(torch.float64), torch.ones(state.shape[0], dtype=torch.bool, device=state.device)

    def observe(self, state):
        return state


def test_lower_bound_is_the_mean_less_z_standard_errors():
    scores = torch.tensor([[1.0, 2.0, 3.0, 4.0], [5.0, 5.0, 5.0, 5.0]], dtype=torch.float64)
    expected = 2.5 - CONFIDENCE_Z * float(torch.tensor([1.0, 2.0, 3.0, 4.0]).std()) / 2.0
    assert held_out_lower_bound(scores).tolist() == pytest.approx([expected, 5.0])
    assert held_out_lower_bound(scores[:, :1]).tolist() == [1.0, 5.0]  # one episode: no spread to estimate


@pytest.mark.parametrize("threshold, confirmed", [(0.40, True), (0.45, False)])
def test_a_run_is_confirmed_only_with_the_margin(threshold, confirmed):
    # held-out mean 0.467 and standard error 0.029: 0.45 lies within 2 standard errors below it, 0.40 beyond
    task = CoinTask()
    config = task_config(task, "sigmoid", pop_size=8)
    neat = NEAT(config, seeds=[0])
    runs = ThresholdRuns(neat, task, "sigmoid", threshold, episodes_per_genome=4, validation_episodes=100)
    runs.run(TaskFitness(task, config, "sigmoid", episodes=4, seed=0), 3)
    record = runs.records[0]
    assert record.train_generation == 1  # the best of 8 x 4 uniform episodes is above either threshold
    assert (record.confirmed_generation == 1) is confirmed
    assert record.champion_from == ("confirmed" if confirmed else "final")
    # every check's best held-out mean reached the threshold: the margin alone decided
    assert all(c is not None and c >= threshold for c in record.checks)
    assert abs(record.champion_validation - 0.5) < 3.0 / math.sqrt(12) / 10.0  # the mean of 100 uniform draws
