import math

import pytest
import torch
from evotorch import SolutionBatch
from evotorch.algorithms import SNES
from evotorch.logging import PandasLogger, StdOutLogger

import evolution.weight_search as ws
from evolution import NEAT, load_genome, make_controller, rollout, save_genome
from evolution.weight_search import FixedTopologyProblem
from tasks.cartpole import CartPoleTask, cartpole_failed
from tasks.studies.cartpole import controller_config, nonmarkov_fitness
from tasks.studies.generalization import (
    grid_ranges,
    make_policy,
    policy_success_rate,
    start_grid,
    steps_from_starts,
    success_rate,
)

SNN_CFG = controller_config("snn", max_hidden=2)  # nodes: 0, 1 inputs; 2 output; 3, 4 hidden
SIG_CFG = controller_config("sigmoid", max_hidden=2)  # nodes: 0, 1 inputs; 2 bias; 3 output; 4, 5 hidden
GROWN_CFG = controller_config("snn", max_hidden=4, pop_size=12, node_add_prob=0.5, conn_add_prob=0.5)
TASK = CartPoleTask.nonmarkov()  # [Qiu19] Table II: x and theta observed, tau 0.01 s


@pytest.fixture(autouse=True)
def _one_thread():
    # The tensors here are tiny ([B, 5]); intra-op threads only add synchronisation. On a shared
    # 2-core machine they made the SNES test ~7x slower.
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _mask(cfg):
    """Inputs (and bias) -> output, input -> hidden -> output, output <-> hidden: recurrent."""
    N, out, h1, h2 = cfg.num_nodes, cfg.first_output, cfg.first_hidden, cfg.first_hidden + 1
    m = torch.zeros(N, N, dtype=torch.bool)
    m[: out, out] = True
    m[0, h1] = m[1, h1] = m[h1, out] = True
    m[out, h2] = m[h2, out] = True
    return m


def _starts():
    """The paper's start and two more, all inside the limits."""
    return torch.tensor([[0.0, 0.0, math.radians(3.0), 0.0], [0.5, -0.2, -0.02, 0.05], [-1.0, 0.3, 0.03, -0.1]])


def _grown():
    neat = NEAT(GROWN_CFG, seeds=[0, 1])
    neat.run(lambda g: g.num_genes().double(), 3)  # hidden nodes and disabled genes
    return neat.genomes


@pytest.mark.parametrize("controller, cfg", [("snn", SNN_CFG), ("sigmoid", SIG_CFG)])
def test_batched_evaluation_equals_each_solution_alone(controller, cfg, monkeypatch):
    # Exact equality: fitness is a mean of integer step counts, and every batch row runs the
    # same float operations on its own data (rows never mix), so batching cannot move a
    # failure step; the rollout's compaction of finished rows is exact too.
    problem = FixedTopologyProblem(cfg, _mask(cfg), task=TASK, controller=controller, starts=_starts(),
                                   max_steps=300, seed=1)
    batch = problem.generate_batch(8)
    loops = []
    real = ws.rollout

    def counted(task, policy, **kwargs):
        loops.append((policy.num_genomes, kwargs["episodes"]))
        return real(task, policy, **kwargs)

    monkeypatch.setattr(ws, "rollout", counted)
    problem.evaluate(batch)
    assert loops == [(8, 3)]  # the whole population x 3 starts: one rollout
    monkeypatch.undo()
    batched = batch.evals.flatten().double()
    assert len(set(batched.tolist())) > 3  # the solutions really differ
    starts = _starts()
    for k in range(8):
        g = problem.to_genomes(batch.values[k])
        per_start = []
        for s in range(3):
            alone = make_controller(g, cfg, TASK, controller)
            result = rollout(TASK, alone, episodes=1, starts=starts[s : s + 1], max_steps=300)
            per_start.append(result.steps.item())
        assert batched[k].item() == sum(per_start) / 3
        assert problem.fitness(batch.values[k]).item() == batched[k].item()


def test_short_snes_run_improves_mean_fitness(capsys):
    problem = FixedTopologyProblem(SNN_CFG, _mask(SNN_CFG), task=TASK, max_steps=500, seed=0)
    torch.manual_seed(0)
    searcher = SNES(problem, popsize=24, stdev_init=1.0, center_init=problem.initial_solution())
    StdOutLogger(searcher, interval=5)
    log = PandasLogger(searcher)
    searcher.run(15)
    mean = log.to_dataframe()["mean_eval"]
    assert len(mean) == 15
    assert mean.iloc[-3:].mean() > 2.0 * mean.iloc[0]  # seeded: ~75 steps vs ~26
    assert "mean_eval" in capsys.readouterr().out
    best = searcher.status["best"]
    g = problem.to_genomes(best)
    assert nonmarkov_fitness("snn", SNN_CFG, max_steps=500)(g).item() == searcher.status["best_eval"]


def test_solution_to_genomes_round_trip(tmp_path):
    pop = _grown()
    problem = FixedTopologyProblem.from_genome(pop, GROWN_CFG, run=1, index=4, task=TASK)
    champion = pop.select_runs([1]).gather(torch.tensor([[4]]))
    assert problem.solution_length == int(champion.enabled.sum()) + 1
    # The start of the search is the champion itself, disabled genes and nodes included.
    back = problem.to_genomes(problem.initial_solution())
    for name in ("weight", "conn", "enabled", "node"):
        assert torch.equal(getattr(back, name), getattr(champion, name)), name
    torch.testing.assert_close(back.sigma, champion.sigma, rtol=1e-6, atol=0)  # exp(log(sigma))
    fit = nonmarkov_fitness("snn", GROWN_CFG, max_steps=300)
    problem300 = FixedTopologyProblem.from_genome(pop, GROWN_CFG, run=1, index=4, task=TASK, max_steps=300)
    assert problem300.fitness(problem.initial_solution()).item() == fit(champion).item()
    # Any solution -> Genomes -> file -> Genomes -> the same solution.
    x = problem.initial_solution() + 0.3 * torch.randn(problem.solution_length, generator=torch.Generator().manual_seed(0))
    g = problem.to_genomes(x)
    path = save_genome(tmp_path / "tuned.json", g, GROWN_CFG)
    loaded = load_genome(path, GROWN_CFG)
    again = FixedTopologyProblem.from_genome(loaded, GROWN_CFG, task=TASK).initial_solution()
    torch.testing.assert_close(again, x, rtol=1e-6, atol=1e-6)
    # Decoding clamps to the config's bounds; a batch decodes to [1, E].
    x[0], x[-1] = 100.0, 10.0
    gb = problem.to_genomes(torch.stack([x, x]))
    i, j = problem.connections[0].tolist()
    assert gb.pop_size == 2 and gb.weight[0, 0, i, j].item() == GROWN_CFG.weight_max_value
    assert gb.sigma[0, 0].item() == GROWN_CFG.sigma_max_value


def test_bad_input_names_the_argument():
    m = _mask(SNN_CFG)
    with pytest.raises(ValueError, match=r"mask must have shape \[N, N\] = \(5, 5\)"):
        FixedTopologyProblem(SNN_CFG, m[:4, :4], task=TASK)
    no_out = m.clone()
    no_out[:, SNN_CFG.first_output] = False
    with pytest.raises(ValueError, match="mask has no connection into output node 2"):
        FixedTopologyProblem(SNN_CFG, no_out, task=TASK)
    into_input = m.clone()
    into_input[3, 0] = True
    with pytest.raises(ValueError, match="mask has connections into input"):
        FixedTopologyProblem(SNN_CFG, into_input, task=TASK)
    with pytest.raises(ValueError, match="mask must be bool"):
        FixedTopologyProblem(SNN_CFG, m.float() * 0.5, task=TASK)
    # Starts are the task's states: any [S, ...] tensor of S >= 1 finite rows.
    for bad in (torch.zeros(0, 4), torch.tensor(0.0), [[0.0, 0.0, 0.0, 0.0]]):
        with pytest.raises(ValueError, match=r"starts must be a \[S, \.\.\.\] tensor of S >= 1 start states"):
            FixedTopologyProblem(SNN_CFG, m, task=TASK, starts=bad)
    with pytest.raises(ValueError, match="starts holds NaN or inf"):
        FixedTopologyProblem(SNN_CFG, m, task=TASK, starts=torch.tensor([[0.0, 0, 0, 0], [float("nan"), 0, 0, 0]]))
    with pytest.raises(ValueError, match="max_steps"):
        FixedTopologyProblem(SNN_CFG, m, task=TASK, max_steps=0)
    with pytest.raises(ValueError, match="controller"):
        FixedTopologyProblem(SNN_CFG, m, task=TASK, controller="lif")
    with pytest.raises(ValueError, match="task must be an evolution.task.Task"):
        FixedTopologyProblem(SNN_CFG, m, task="cartpole")
    problem = FixedTopologyProblem(SNN_CFG, m, task=TASK)
    assert problem.solution_length == int(m.sum()) + 1
    with pytest.raises(ValueError, match=r"solution must have length 8 \(7 weights, ln sigma\), got shape \(7,\)"):
        problem.to_genomes(torch.zeros(7))
    with pytest.raises(ValueError, match="solution holds NaN"):
        problem.to_genomes(torch.full((8,), float("nan")))


def test_start_grid_has_625_distinct_states_inside_the_limits():
    grid = start_grid()
    assert grid.shape == (625, 4)
    assert torch.unique(grid, dim=0).shape[0] == 625
    assert not bool(cartpole_failed(grid).any())
    for col, a in enumerate(grid_ranges()):
        values = torch.unique(grid[:, col].double())
        expected = a * torch.tensor([-0.9, -0.5, 0.0, 0.5, 0.9], dtype=torch.float64)
        torch.testing.assert_close(values, expected, rtol=1e-6, atol=1e-7)
    assert grid[:, 0].abs().max().item() == pytest.approx(0.9 * 0.9 * 2.4, rel=1e-6)  # 0.95 of +-2.16 m
    assert grid[:, 2].abs().max().item() == pytest.approx(math.radians(0.9 * 3.6), rel=1e-6)


class _ConstantPush:
    """A controller (``evolution.task.Controller``) of ``num_genomes`` genomes that always pushes +10 N."""

    dtype, device = torch.float32, torch.device("cpu")

    def __init__(self, num_genomes):
        self.num_genomes = num_genomes

    def initial_state(self, network):
        return network

    def select(self, state, keep):
        return state[keep]

    def act(self, obs01, state):
        return torch.full((obs01.shape[0], 1), 10.0), state, torch.zeros(obs01.shape[0], 1)


def test_success_rate_is_zero_for_a_constant_push():
    rate = policy_success_rate(_ConstantPush(2))
    assert rate.tolist() == [0.0, 0.0]


def test_success_rate_matches_a_per_start_loop():
    pop = _grown().gather(torch.tensor([[0, 2, 4], [0, 9, 11]]))
    starts = start_grid()[::104]  # 7 of the 625
    T = 30
    rate = success_rate(pop, GROWN_CFG, starts=starts, steps=T)
    assert rate.shape == (2, 3)
    # 6 controllers x 7 starts as one rollout (C kernel, finished rows dropped), ...
    batched = steps_from_starts(make_policy(pop, GROWN_CFG), starts, max_steps=200)
    assert batched.shape == (6, 7)
    # ... as the same batch through the torch network step, ...
    torch_step = steps_from_starts(make_policy(pop, GROWN_CFG, backend="torch"), starts, max_steps=200)
    assert torch.equal(torch_step, batched)
    # ... and each controller alone from each start.
    task = CartPoleTask.nonmarkov(max_steps=200)
    loop = torch.zeros(6, 7, dtype=torch.long)
    for c in range(6):
        one = pop.select_runs([c // 3]).gather(torch.tensor([[c % 3]]))
        for s in range(7):
            alone = make_controller(one, GROWN_CFG, task)
            loop[c, s] = rollout(task, alone, starts=starts[s : s + 1]).steps.item()
    assert torch.equal(batched, loop)
    expected = (loop >= T).double().mean(-1).view(2, 3)
    assert torch.equal(rate, expected)
    assert 0.0 < rate.min().item() < 1.0 or 0.0 < rate.max().item() < 1.0  # a non-trivial case


def test_num_actors_two_on_local_ray_matches_local_evaluation():
    ray = pytest.importorskip("ray")
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)  # a fresh local Ray
    try:
        problem = FixedTopologyProblem(SNN_CFG, _mask(SNN_CFG), task=TASK, max_steps=200, seed=0, num_actors=2)
        searcher = SNES(problem, popsize=16, stdev_init=1.0, center_init=problem.initial_solution())
        log = PandasLogger(searcher)
        searcher.run(2)
        assert problem.actors is not None and len(problem.actors) == 2
        assert len(log.to_dataframe()) == 2
        pop: SolutionBatch = searcher.population
        local = FixedTopologyProblem(SNN_CFG, _mask(SNN_CFG), task=TASK, max_steps=200)
        assert torch.equal(pop.evals.flatten().double(), local.fitness(pop.values))
    finally:
        ray.shutdown()
