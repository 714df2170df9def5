"""gymnasium environments as tasks of the seam."""

import pytest
import torch

gym = pytest.importorskip("gymnasium")

from evolution import NEAT, NEATConfig, TaskError, TaskFitness, make_controller, rollout, spiking_config  # noqa: E402
from tasks.gym_adapter import GymTask  # noqa: E402

CARTPOLE_BOUNDS = ((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))


def test_cartpole_evolves_and_every_genome_sees_the_seeded_starts():
    task = GymTask("CartPole-v1", observation_bounds=CARTPOLE_BOUNDS, max_steps=200, adapter=True)  # not the port
    assert (task.observation_size, task.action_size, task.discrete, task.max_steps) == (4, 1, 2, 200)
    starts = task.reset(3, torch.Generator().manual_seed(5))
    for k in range(3):  # each episode's start is its seed's reset
        env = gym.make("CartPole-v1")
        obs, _ = env.reset(seed=int(starts[k, 0]))
        assert torch.equal(starts[k, 3:], torch.as_tensor(obs, dtype=torch.float64))
    cfg = spiking_config(num_inputs=4, num_outputs=1, pop_size=12, max_hidden=3)
    fitness = TaskFitness(task, cfg, "snn", episodes=2, seed=1)
    neat = NEAT(cfg, seeds=[0])
    first = fitness(neat.ask())
    assert first.shape == (1, 12) and bool((first >= 8).all())  # CartPole pays 1 per step, and falls after ~10
    result = neat.run(fitness, generations=3)
    assert float(result.best_fitness[0]) >= float(first.max())
    g = neat.ask()
    again = fitness(g)
    assert torch.equal(again, fitness(g))  # seeded: the same fitness twice
    alone = TaskFitness(task, cfg, "snn", episodes=2, seed=1)(g.gather(torch.tensor([[4]])))
    assert torch.equal(alone[0, 0], again[0, 4])  # and alone as in the batch


def test_continuous_actions_scale_to_the_box_and_sigmoid_controllers_run_too():
    task = GymTask("Pendulum-v1", max_steps=30)
    assert (task.discrete, task.action_size, task.action_max) == (0, 1, 2.0)
    cfg = NEATConfig(num_inputs=3, num_outputs=1, num_bias=1, pop_size=5)
    result = rollout(task, make_controller(NEAT(cfg, seeds=[0]).ask(), cfg, task, "sigmoid"), episodes=2,
                     seed=3, record=True)
    assert result.returns.shape == (5, 2) and bool((result.returns < 0).all())  # Pendulum's reward is a cost
    assert bool((result.steps == 30).all()) and float(result.trace["action"].abs().max()) <= 2.0


def test_unusable_spaces_are_named():
    with pytest.raises(TaskError, match=r"observation variables \[1, 3\] have infinite bounds"):
        GymTask("CartPole-v1")
    with pytest.raises(TaskError, match="observation_bounds must give 4"):
        GymTask("CartPole-v1", observation_bounds=((0.0,), (1.0,)))
