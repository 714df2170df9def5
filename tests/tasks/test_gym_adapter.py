"""gymnasium environments as tasks of the seam."""

import pickle

import numpy as np
import pytest
import torch

gym = pytest.importorskip("gymnasium")

from evolution import NEAT, NEATConfig, TaskError, TaskFitness, make_controller, rollout, spiking_config  # noqa: E402
from tasks.gym_adapter import GymTask, estimate_bounds, flat_space  # noqa: E402
from tasks.gym_cartpole import GymCartPoleTask  # noqa: E402

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


def test_unbounded_variables_get_the_ports_bounds_or_an_estimate_from_random_actions():
    port, own = GymTask("CartPole-v1"), GymCartPoleTask()
    space = gym.make("CartPole-v1").observation_space
    assert type(port) is GymCartPoleTask  # velocities: the port's bounds; the rest: the space's
    assert port.observation_high == (float(space.high[0]), own.observation_high[1], float(space.high[2]),
                                     own.observation_high[3])
    adapter = GymTask("CartPole-v1", adapter=True)
    assert adapter.estimated_bounds == [1, 3]
    assert adapter.observation_high[0] == float(space.high[0]) and adapter.observation_low[2] == float(space.low[2])
    assert GymTask("CartPole-v1", adapter=True).observation_high == adapter.observation_high  # seeded: the same
    # the estimate holds what random actions see, with room to spare (twice the 1-99 % spread)
    env = gym.make("CartPole-v1")
    env.reset(seed=123)
    env.action_space.seed(123)
    seen = []
    for _ in range(200):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        seen.append(obs)
        if terminated or truncated:
            break
    seen = np.stack(seen)
    for k in (1, 3):
        assert adapter.observation_low[k] < seen[:, k].min() and seen[:, k].max() < adapter.observation_high[k]
        assert adapter.observation_high[k] - adapter.observation_low[k] < 20.0  # not a vacuous range


class _Scripted:
    """An environment whose observations are given rows (random actions change nothing)."""

    def __init__(self, rows):
        self.rows, self.t = rows, 0
        self.action_space = gym.spaces.Discrete(2)

    def step(self, action):
        self.t += 1
        return self.rows[min(self.t, len(self.rows) - 1)], 0.0, False, self.t >= len(self.rows) - 1, {}

    def close(self):
        pass


def test_estimate_bounds_keeps_given_sides_and_opens_still_variables():
    rows = [np.array([3.0, 0.1 * t, 5.0 + 0.01 * t]) for t in range(101)]  # constant, 0..10, 5..6
    low = np.array([-np.inf, 0.0, -np.inf])
    high = np.array([np.inf, np.inf, 2.0])  # the third's given high lies below all it takes
    lo, hi = estimate_bounds(lambda seed: (_Scripted(rows), rows[0]), np.asarray, low, high, max_steps=100)
    assert (lo[0], hi[0]) == (2.0, 4.0)  # a variable that does not move: +-1 about its value
    assert lo[1] == 0.0 and 10.0 < hi[1] < 20.0  # the given low kept; the high past what was seen
    assert hi[2] == 2.0 and lo[2] < 2.0  # the given high kept; the estimate opened below it
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))


def test_discrete_and_tuple_observations_are_flattened_one_hot():
    lake = GymTask("FrozenLake-v1")
    assert (lake.observation_size, lake.discrete, lake.action_size, lake.estimated_bounds) == (16, 4, 4, [])
    assert lake.observation_low == (0.0,) * 16 and lake.observation_high == (1.0,) * 16
    starts = lake.reset(2, torch.Generator().manual_seed(0))
    assert torch.equal(lake.observe(starts)[:, 0], torch.ones(2, dtype=torch.float64))  # the start square
    moved, _, _ = lake.step(starts, torch.tensor([[0.0, 0.1, 0.2, 0.9]] * 2))  # the largest output: up
    seen = lake.observe(moved)
    assert bool((seen.sum(1) == 1).all()) and bool(((seen == 0) | (seen == 1)).all())
    cards = GymTask("Blackjack-v1")
    assert cards.observation_size == 32 + 11 + 2
    cfg = NEATConfig(num_inputs=16, num_outputs=4, num_bias=1, pop_size=4)
    result = rollout(lake, make_controller(NEAT(cfg, seeds=[0]).ask(), cfg, lake, "sigmoid"), episodes=2, seed=1)
    assert result.returns.shape == (4, 2) and bool(((result.returns == 0) | (result.returns == 1)).all())


def test_environments_are_reused_across_rollouts_with_the_results_of_fresh_ones():
    lake = GymTask("FrozenLake-v1")  # slippery: the moves are drawn from each environment's seeded generator
    cfg = NEATConfig(num_inputs=16, num_outputs=4, num_bias=1, pop_size=6)
    genomes = NEAT(cfg, seeds=[0]).ask()

    def returns(task, seed):
        return rollout(task, make_controller(genomes, cfg, task, "sigmoid"), episodes=3, seed=seed).returns

    first, other, again = returns(lake, 1), returns(lake, 2), returns(lake, 1)
    assert torch.equal(first, again)  # the reused environments start each episode from its seed
    assert torch.equal(other, returns(GymTask("FrozenLake-v1"), 2))  # as fresh ones do
    assert len(lake._envs) + len(lake._pool) <= 18 + 18  # one per row stepped, and the starts' own
    copy = pickle.loads(pickle.dumps(lake))  # environments stay with their process
    assert (copy._envs, copy._pool) == ([], []) and torch.equal(returns(copy, 1), first)


def test_unordered_discrete_actions_take_one_output_each_and_step_the_largest():
    lake = GymTask("FrozenLake-v1")  # Discrete(4): left, down, right, up, in no order
    assert (lake.discrete_actions, lake.action_size) == ("argmax", 4)
    outputs = torch.tensor([[0.1, 0.9, 0.2, 0.3], [0.5, 0.5, 0.1, 0.0], [-1.0, -1.0, -1.0, -0.5], [-1.0] * 4])
    assert lake._actions(outputs) == [1, 0, 3, 0]  # the largest; the first of a tie
    lake._action_start = -1  # a Discrete(4, start=-1) space: the same picks, as its actions
    assert lake._actions(outputs) == [0, -1, 2, -1]
    binned = GymTask("FrozenLake-v1", discrete_actions="bins")  # asked for: one output in 4 ordered bins
    assert (binned.discrete_actions, binned.action_size) == ("bins", 1)
    assert binned._actions(torch.tensor([[-0.9], [-0.4], [0.1], [0.9]])) == [0, 1, 2, 3]
    cart = GymTask("CartPole-v1", adapter=True)  # Discrete(2): one output, its sign
    assert (cart.discrete_actions, cart.action_size, cart._actions(torch.tensor([[-0.2], [0.2]]))) == ("bins", 1, [0, 1])
    assert GymTask("Pendulum-v1", adapter=True).discrete_actions is None  # a Box
    with pytest.raises(TaskError, match="discrete_actions must be one of"):
        GymTask("FrozenLake-v1", discrete_actions="softmax")
    with pytest.raises(TaskError, match=r"discrete_actions .* Discrete action space \(this one is Box"):
        GymTask("Pendulum-v1", discrete_actions="argmax")


def test_category_observations_mark_the_task_and_measurements_do_not():
    assert GymTask("FrozenLake-v1").discrete_observations  # Discrete(16)
    assert GymTask("Blackjack-v1").discrete_observations  # a Tuple of Discrete spaces
    assert not GymTask("CartPole-v1", adapter=True).discrete_observations  # a Box
    assert not GymTask("CartPole-v1").discrete_observations  # the port, as the Task default
    lake = GymTask("FrozenLake-v1")
    lake.discrete_observations = 1  # not a bool: named, not read as truthy
    with pytest.raises(TaskError, match="discrete_observations = 1 must be True or False"):
        lake.validate()


def test_discrete_observations_one_hot_as_gymnasium_flattens_them():
    lake = GymTask("FrozenLake-v1")
    for space in (gym.spaces.Discrete(16), gym.spaces.Discrete(5, start=-2)):
        lake._space = space
        for obs in range(space.start, space.start + space.n):
            vector = lake._vector(np.int64(obs))
            assert vector.dtype == np.float64 and np.array_equal(vector, gym.spaces.flatten(space, obs))


def test_unusable_spaces_are_named():
    with pytest.raises(TaskError, match="observation_bounds must give 4"):
        GymTask("CartPole-v1", observation_bounds=((0.0,), (1.0,)))
    with pytest.raises(TaskError, match=r"'seq-task': the observation space Sequence.* does not flatten to one vector"):
        flat_space("seq-task", gym.spaces.Sequence(gym.spaces.Discrete(2)))
