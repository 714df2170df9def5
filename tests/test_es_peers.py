"""The evolution-strategy peers of ``benchmarks/classic_control_vs_es.py`` (``benchmarks/es_peers.py``):
the batched rollout against a loop over members, the greedy head on Discrete ports, OpenES's update,
and the script's tiny run."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("gymnasium")
BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import es_peers  # noqa: E402
from es_peers import MLP, PGPE, OpenES, bin_centres, centered_ranks, peer_returns  # noqa: E402

from evolution.rollout import episode_starts, rollout  # noqa: E402
from tasks.gym_adapter import GymTask, discrete_action  # noqa: E402
from tasks.studies.env_task import gym_task  # noqa: E402


@pytest.fixture(autouse=True)
def one_thread():
    """One torch thread, as the script runs by default (small batched matmuls on a busy machine
    cost many times more with a thread pool)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.mark.parametrize("env_id, hidden, activation, raw", [
    ("CartPole-v1", (16,), "tanh", False),  # episodes end at different steps: the batch is compacted
    ("MountainCar-v0", (64, 64), "relu", True),
    ("Pendulum-v1", (64, 64), "relu", True),
    ("Pendulum-v1", (16,), "tanh", False),
])
def test_batched_rollout_equals_a_loop_over_members(env_id, hidden, activation, raw, monkeypatch):
    selects = []
    select = es_peers.MLPController.select
    monkeypatch.setattr(es_peers.MLPController, "select",
                        lambda self, state, keep: selects.append(len(keep)) or select(self, state, keep))
    task, _ = gym_task(env_id)
    mlp = MLP.for_task(task, hidden, activation)
    params = torch.randn(4, mlp.num_params, generator=torch.Generator().manual_seed(3)) * 0.3
    batched = peer_returns(task, mlp, params, episodes=5, seed=11, raw_observations=raw)
    looped = torch.cat([peer_returns(task, mlp, params[g:g + 1], episodes=5, seed=11, raw_observations=raw)
                        for g in range(4)])
    assert batched.shape == (4, 5) and batched.dtype == torch.float64
    # the same episodes to float32 rounding (a 1-output layer's bmm rounds by batch size; Pendulum is chaotic)
    torch.testing.assert_close(batched, looped, rtol=1e-3, atol=1e-3)
    if env_id == "CartPole-v1":  # episodes ended at different steps, and the finished ones were dropped
        assert len(set(batched.flatten().tolist())) > 1 and selects


def test_controller_acts_like_a_plain_mlp_on_the_task_interface():
    """One member's first action by hand: tanh MLP on the bound-normalised (or raw) observation,
    tanh output x action_max."""
    task, _ = gym_task("Pendulum-v1")
    mlp = MLP.for_task(task, (16,), "tanh")
    params = torch.randn(3, mlp.num_params, generator=torch.Generator().manual_seed(5))
    starts = episode_starts(task, 2, 7)
    obs = task.observe(starts)
    low, high = task.bounds()
    for raw in (False, True):
        controller = es_peers.MLPController(mlp, params, task, raw_observations=raw)
        trace = rollout(task, controller, episodes=2, starts=starts, max_steps=1, record=True).trace
        x = obs if raw else (obs - (low + high) / 2) / ((high - low) / 2)
        for g in range(3):
            (w1, b1), (w2, b2) = [(w[g], b[g, 0]) for w, b in mlp.layers(params)]
            expected = torch.tanh(torch.tanh(x @ w1 + b1) @ w2 + b2) * task.action_max
            torch.testing.assert_close(trace["action"][0, g * 2:(g + 1) * 2], expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("env_id, outputs, discrete", [
    ("CartPole-v1", 2, 2), ("Acrobot-v1", 3, 3), ("MountainCar-v0", 3, 3), ("Pendulum-v1", 1, 0),
    ("MountainCarContinuous-v0", 1, 0),
])
def test_the_head_is_n_logits_on_a_discrete_port_and_one_output_per_action_on_a_box(env_id, outputs, discrete):
    task, _ = gym_task(env_id)
    mlp = MLP.for_task(task, (16,), "tanh")
    assert mlp.sizes == (task.observation_size, 16, outputs) and mlp.discrete == discrete == task.discrete
    assert mlp.num_params == task.observation_size * 16 + 16 + 16 * outputs + outputs
    wrong = MLP((task.observation_size, 16, 1 if discrete else 2))  # the other head
    with pytest.raises(ValueError, match="does not fit"):
        es_peers.MLPController(wrong, torch.zeros(1, wrong.num_params), task, raw_observations=True)
    with pytest.raises(ValueError, match="discrete"):
        MLP((4, 16, 2), discrete=3)


@pytest.mark.parametrize("n", [2, 3])
def test_bin_centres_round_trip_through_the_ports_binning(n):
    """The value fed for action k is the centre of bin k, -1 + (2k + 1) / n, and the port's
    binning (``discrete_action``, float64 from the action widened, as the torch and C steps and
    ``GymTask`` bin) maps it back to k exactly, in float32 (the controller's) and float64."""
    env_id = {2: "CartPole-v1", 3: "Acrobot-v1"}[n]
    port, _ = gym_task(env_id)  # its bounds (CartPole's velocities are unbounded in gymnasium's space)
    adapter = GymTask(env_id, adapter=True, discrete_actions="bins",
                      observation_bounds=(port.observation_low, port.observation_high))
    assert adapter.discrete == n
    expected = [-1.0 + (2 * k + 1) / n for k in range(n)]
    assert bin_centres(n, torch.float64).tolist() == expected
    assert bin_centres(n).dtype == torch.float32
    assert bin_centres(n).tolist() == torch.tensor(expected, dtype=torch.float32).tolist()
    for dtype in (torch.float32, torch.float64):
        centres = bin_centres(n, dtype)
        assert discrete_action(centres.view(-1, 1), n).tolist() == [float(k) for k in range(n)]
        # as the adapter bins its rows (GymTask._actions, on an environment with Discrete(n) actions)
        assert adapter._actions(centres.view(-1, 1)) == list(range(n))
    if n == 2:
        assert expected == [-0.5, 0.5]
    else:
        assert expected[1] == 0.0 and expected == pytest.approx([-2 / 3, 0.0, 2 / 3], abs=1e-15)


@pytest.mark.parametrize("env_id, raw", [("CartPole-v1", False), ("CartPole-v1", True), ("Acrobot-v1", False),
                                         ("Acrobot-v1", True)])
def test_the_greedy_policy_picks_the_action_whose_index_the_port_takes(env_id, raw):
    """Every member's first steps: the argmax k of its n logits (the MLP by hand), fed as the
    centre of bin k, and the port's next state is gymnasium's step with action k from the same
    state (and no other action's)."""
    gym = pytest.importorskip("gymnasium")
    task, _ = gym_task(env_id)
    n = task.discrete
    mlp = MLP.for_task(task, (16,), "tanh")
    G, E, T = 6, 4, 3
    params = torch.randn(G, mlp.num_params, generator=torch.Generator().manual_seed(2)) * 0.5
    starts = episode_starts(task, E, 9, dtype=torch.float64)
    controller = es_peers.MLPController(mlp, params, task, raw_observations=raw)
    trace = rollout(task, controller, episodes=E, starts=starts, max_steps=T, record=True).trace
    low, high = (b.to(torch.float64) for b in task.bounds(dtype=torch.float64))
    layers = [(w.to(torch.float64), b.to(torch.float64)[:, 0]) for w, b in mlp.layers(params)]
    member = torch.arange(G * E) // E
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    picked = set()
    for t in range(T):
        before = starts.repeat(G, 1) if t == 0 else trace["state"][t - 1]
        obs = trace["observation"][t].to(torch.float64)
        x = obs if raw else (obs - (low + high) / 2) / ((high - low) / 2)
        (w1, b1), (w2, b2) = layers
        logits = torch.einsum("bh,bho->bo", torch.tanh(torch.einsum("bi,bih->bh", x, w1[member]) + b1[member]),
                              w2[member]) + b2[member]
        k = logits.argmax(1)
        top2 = logits.topk(2, dim=1).values
        assert bool(((top2[:, 0] - top2[:, 1]) > 1e-4).all())  # no near-ties: float32 picks the same k
        action = trace["action"][t]
        assert action.shape == (G * E, 1)
        torch.testing.assert_close(action[:, 0], bin_centres(n)[k])
        assert torch.equal(discrete_action(action, n), k.to(torch.float64))
        for r in range(G * E):
            nexts = []
            for a in range(n):
                env.state = before[r].numpy().astype(np.float64).copy()
                env.step(a)
                nexts.append(np.asarray(env.state, dtype=np.float64))
            port = trace["state"][t][r].numpy()
            gaps = [float(np.abs(port - s).max()) for s in nexts]
            assert gaps[int(k[r])] < 1e-9 and all(g > 1e-4 for a, g in enumerate(gaps) if a != int(k[r])), gaps
        picked.update(k.tolist())
    assert len(picked) >= 2  # the policies do not all push one way


def test_centered_ranks():
    u = centered_ranks(torch.tensor([3.0, -1.0, 10.0, 0.0, 5.0]))
    assert u.tolist() == [0.0, -0.5, 0.5, -0.25, 0.25]  # worst -0.5, best +0.5


def test_openes_antithetic_ranks_move_the_mean_towards_the_optimum():
    target = torch.tensor([1.0, -2.0, 0.5, 3.0, -1.0], dtype=torch.float64)
    es = OpenES(5, popsize=20, sigma_init=0.1, sigma_decay=0.999, sigma_limit=0.01, lrate_init=0.05,
                lrate_decay=0.999, lrate_limit=0.001, seed=0)
    x = es.ask()
    assert x.shape == (20, 5)
    torch.testing.assert_close(x[:10] - es.mean, -(x[10:] - es.mean))  # antithetic pairs
    before = (es.mean - target).norm()
    es.tell(x, -((x - target) ** 2).sum(1))  # maximise -||x - target||^2
    # Adam's first step is lrate x the estimated gradient's sign in every coordinate, and goes uphill
    torch.testing.assert_close(es.mean.abs(), torch.full((5,), 0.05, dtype=torch.float64), rtol=1e-6, atol=1e-9)
    assert (es.mean - target).norm() < before and float(es.mean @ target) > 0
    for _ in range(60):
        x = es.ask()
        es.tell(x, -((x - target) ** 2).sum(1))
    assert (es.mean - target).norm() < 0.5 * before
    assert es.sigma == pytest.approx(0.1 * 0.999 ** 61) and es.lrate == pytest.approx(0.05 * 0.999 ** 61)


def test_openes_weight_decay_pulls_towards_zero():
    """With a flat fitness, only the weight decay ranks the members: the mean shrinks."""
    es = OpenES(3, popsize=50, sigma_init=0.1, sigma_decay=1.0, sigma_limit=0.01, lrate_init=0.01,
                lrate_decay=1.0, lrate_limit=0.001, w_decay=1.0, seed=1)
    es.mean = torch.tensor([1.0, -1.0, 2.0], dtype=torch.float64)
    for _ in range(20):
        x = es.ask()
        es.tell(x, torch.zeros(50))
    assert (es.mean.abs() < torch.tensor([1.0, 1.0, 2.0]) - 0.05).all()


def test_pgpe_climbs_and_keeps_the_global_random_stream():
    target = torch.tensor([0.5, -0.5, 1.0])
    pgpe = PGPE(3, popsize=20, center_learning_rate=0.075, max_speed=0.15, momentum=0.9, radius_init=0.5,
                stdev_learning_rate=0.1, stdev_max_change=0.2, seed=0)
    torch.manual_seed(123)
    expected = torch.rand(3)
    torch.manual_seed(123)
    for _ in range(30):
        x = pgpe.ask()
        pgpe.tell(x, -((x - target) ** 2).sum(1))
    assert torch.equal(torch.rand(3), expected)  # its sampling used a stream of its own
    assert (pgpe.center - target).norm() < 0.5 * target.norm()


def test_tiny_run_writes_the_table_and_the_json(tmp_path):
    import classic_control_vs_es as vs

    out = tmp_path / "vs"
    argv = ["--envs", "CartPole-v1", "--seeds", "0", "--budget-episodes", "2400", "--out", str(out), "--quiet"]
    assert vs.main(argv) == 0
    table = (out / "summary.md").read_text()
    assert "| environment | threshold | method |" in table
    for method in vs.METHODS:
        assert f"| CartPole-v1 | 475 | {method} |" in table
    results = json.loads((out / "results.json").read_text())
    assert results["command"].endswith(" ".join(argv))
    assert results["budget_episodes"] == {"CartPole-v1": 2400} and results["threads"] == 1
    assert results["settings"]["pgpe"]["max_speed"]["value"] == 0.15
    assert "source" in results["settings"]["openes"]["CartPole-v1"]["sigma_init"]
    for settings in (results["settings"]["pgpe"], results["settings"]["openes"]["CartPole-v1"]):
        assert settings["output"]["value"].startswith("Discrete(n) ports: n logits, greedy (argmax k)")
    assert set(results["settings"]["ours"]["CartPole-v1"]) == {"snn", "sigmoid"}
    assert [r["method"] for r in results["runs"]] == list(vs.METHODS)
    fields = {"env", "method", "seed", "threshold", "reached", "generation", "episodes", "validation_episodes",
              "episodes_to_threshold", "cpu_s_to_threshold", "cpu_s", "history", "checks", "champion_from",
              "champion_validation", "test_mean", "test_worst", "test_reaches"}
    for run in results["runs"]:
        assert fields <= set(run), fields - set(run)
        assert run["test_episodes"] == 100 and run["validation_episodes"] >= 100 and run["episodes"] <= 2400
        assert run["reached"] == (run["episodes_to_threshold"] is not None)
        if run["method"] in ("pgpe", "openes"):  # two logits on CartPole: 4-16-2 and 4-64-64-2
            assert run["discrete"] == 2 and run["mlp_sizes"] == ([4, 16, 2] if run["method"] == "pgpe"
                                                                 else [4, 64, 64, 2])
    assert {row["method"] for row in results["summary"]} == set(vs.METHODS)
    assert all(row["n"] == 1 for row in results["summary"])


def test_a_budget_below_one_generation_is_one_line_and_status_2(tmp_path, capsys):
    import classic_control_vs_es as vs

    assert vs.main(["--envs", "CartPole-v1", "--methods", "openes", "--seeds", "0", "--budget-episodes", "100",
                    "--out", str(tmp_path), "--quiet"]) == 2
    assert "less than one openes generation" in capsys.readouterr().err
