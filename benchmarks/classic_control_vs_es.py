"""NEAT-SNN and sigmoid NEAT against two evolution-strategy peers on gymnasium's five
classic-control environments: the same batched torch ports, the same machine, the same seeds,
the same success criterion (issue 48, item 3).

    python benchmarks/classic_control_vs_es.py                      # everything, seeds 0-4
    python benchmarks/classic_control_vs_es.py --envs Pendulum-v1 --methods pgpe sigmoid --seeds 0 1
    python benchmarks/classic_control_vs_es.py --envs CartPole-v1 --seeds 0 --budget-episodes 6000 --out /tmp/vs

What runs, per environment (``tasks.studies.env_task.gym_task(env_id)``: the port and its
threshold; CartPole-v1 475, Acrobot-v1 -100, MountainCar-v0 -110, MountainCarContinuous-v0 90,
Pendulum-v1 -200), method and seed, within ``--budget-episodes`` training episodes per run:

* ``pgpe``: EvoTorch's PGPE (``evotorch.algorithms.functional.pgpe``) with ClipUp and centered
  ranks on a ``tanh`` MLP obs-16-act (act: n logits on a Discrete(n) environment, e.g. 4-16-2 on
  CartPole; 3-16-1 on Pendulum), population 100, 20 episodes per member.
* ``openes``: OpenAI-ES (``es_peers.OpenES``, evosax 0.1.x's algorithm in torch) on a 64-64
  ``relu`` MLP, population 100, 20 episodes per member, as RobertTLange/gymnax-blines trains it.
* ``snn``, ``sigmoid``: ``snn-neat evolve ENV --controller snn|sigmoid --seed S --episodes B``,
  i.e. ``tasks.studies.evolve_env.run_plan`` with the library's defaults, one run per seed
  (``EvolvePlan(env, controller, seeds=(S,), episodes=B)``), so its CPU seconds are one run's, as
  the peers' are (``--runs 5`` would batch the five seeds into one population and share the cost).

The peers' members are rolled out batched: every member x episode of a generation is one batch
through the port's ``reset``/``step``/``observe`` (``evolution.rollout.rollout`` with a batched MLP
controller, ``es_peers.MLPController``: the same loop, finished-episode handling and compaction
that runs our controllers, except that ours run whole episodes in C where they can). Every member
of a generation faces the same 20 fresh episodes (new starts each generation, from a stream
seeded by the run's seed). Actions, as the peers configure them: on a Discrete(n) port
(CartPole-v1, Acrobot-v1, MountainCar-v0) n logits, greedy (the argmax k; EvoTorch's ``GymNE``
gives a Discrete(n) environment n outputs and takes their argmax, gymnax-blines n logits of a
categorical it samples), fed to the port as the centre of its bin k, ``-1 + (2k + 1) / n``,
which the port's binning (``tasks.gym_adapter.discrete_action``, the one our controllers' single
output goes through) maps back to k exactly; on a Box port ``tanh`` outputs scaled by
``task.action_max``. Inputs: PGPE sees the
observations normalised by the port's bounds, ``(obs - mid) / half`` unclipped (a fixed stand-in
for EvoTorch's running ``observation_normalization``); OpenES sees the raw observations, as
gymnax-blines' networks do.

Success criterion, the same for all (``tasks.studies.threshold_runs`` for ours): a run reaches
the threshold at the first generation whose candidate has a mean return >= threshold on 100
held-out episodes (seed ``VALIDATION_SEED + seed``, the same every generation, never used for
training). A peer's candidates are the distribution's centre (after that generation's update) and
the generation's best member, checked whenever the best member's training mean (20 episodes)
reaches the threshold; ours are the five fittest genomes at the threshold. The passing candidate
(the better of the passing ones) is tested on 100 fresh episodes (seed ``TEST_SEED + seed``).
A run that never passes is tested with the best on the held-out episodes of its final candidates
(peers: the final centre, the last generation's best member and the best-ever member by
training mean; ours: ``threshold_runs``' pick). Training episodes, held-out episodes and test
episodes are counted apart; CPU seconds are ``time.process_time()`` of this process (one
thread by default, ``--threads``) up to the end of the generation that passed, its check
included.

Output in ``--out`` (default ``results/classic_control_vs_es/``), each file written atomically and
rewritten after every run: ``summary.md`` (the table: per environment x method, runs whose test
mean is >= the threshold k/n, runs that reached it on the held-out episodes k/n, the median
training episodes and CPU seconds to the threshold over all runs, a run that never reached it
counting as never, so "> budget" where the median run did not, and the median test mean) and
``results.json`` (the command, every setting with its source, every run with its per-generation
best training mean and held-out checks, the summary).

Where each peer setting comes from (the constants ``PGPE_SETTINGS`` and ``OPENES_SETTINGS`` below
cite them one by one):

* PGPE: EvoTorch's own example of functional PGPE on a gym classic-control task,
  ``examples/notebooks/Functional_API/problem.ipynb`` of nnaisense/evotorch (CartPole-v1,
  "Linear(obs_length, 16) >> Tanh() >> Linear(16, act_length)", popsize 100, zero centre,
  ``max_speed = 0.15``, ``radius = 15 * max_speed``, ``stdev_learning_rate = 0.1``,
  ``stdev_max_change = 0.2``, ``ranking_method = "centered"``, ``optimizer = "clipup"``,
  ``symmetric = True``), with ``center_learning_rate = max_speed / 2``: ClipUp's recommendation
  (Toklu et al. 2020), which EvoTorch's ``examples/notebooks/Gym_Experiments_with_PGPE_and_CoSyNE.ipynb``
  follows (that notebook: ``max_speed = radius_init / 15``, ``center_learning_rate = max_speed / 2.``,
  ``momentum = 0.9``); the functional notebook itself uses ``0.75 * max_speed``. 20 episodes per
  member: the issue's measurement (EvoTorch's ``GymNE`` defaults to 1).
* OpenES: RobertTLange/gymnax-blines ``agents/CartPole-v1/es.yaml`` and ``agents/Acrobot-v1/es.yaml``
  (sigma 0.03, lrate 0.04), ``agents/Pendulum-v1/es.yaml`` (sigma 0.05, lrate 0.125); all three:
  popsize 100, 20 train rollouts, Adam, sigma and lrate decay 0.999 to floors 0.01 and 0.001,
  centered ranks, no weight decay (``w_decay: 0.0``), a 64-64 relu MLP. gymnax-blines trains
  MountainCar-v0 and MountainCarContinuous-v0 with SimpleGA, not OpenES (``agents/MountainCar-v0/
  es.yaml``, ``agents/MountainCarContinuous-v0/es.yaml``), so here they take the discrete-action
  (CartPole/Acrobot) and the continuous-action (Pendulum) OpenES settings respectively. Adam's
  beta_1 0.99, beta_2 0.999, eps 1e-8 and the zero initial mean are evosax 0.1.3's defaults
  (``evosax/utils/optimizer.py``, ``evosax/strategies/open_es.py``), the evosax of gymnax-blines'
  last commit (April 2023). gymnax-blines' output heads sample: a categorical over n logits, or a
  Gaussian with a learned variance; here both peers keep the n logits on a Discrete(n)
  environment but act greedily (their argmax, as EvoTorch's ``GymNE`` does), and use deterministic
  ``tanh`` outputs on a Box one, so every method is checked and tested as a deterministic policy.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))  # es_peers, beside this file

from es_peers import MLP, PGPE, OpenES, peer_returns  # noqa: E402

from evolution.checkpoint import atomic_write_bytes  # noqa: E402
from tasks.studies.env_task import gym_task  # noqa: E402
from tasks.studies.registry import ReproduceError  # noqa: E402
from tasks.studies.threshold_runs import TEST_EPISODES, TEST_SEED, VALIDATION_EPISODES, VALIDATION_SEED  # noqa: E402

__all__ = ["ENVIRONMENTS", "METHODS", "DEFAULT_BUDGETS", "PGPE_SETTINGS", "OPENES_SETTINGS", "run_peer", "run_ours",
           "summarise", "summary_markdown", "main"]

ENVIRONMENTS = ("CartPole-v1", "Acrobot-v1", "MountainCar-v0", "MountainCarContinuous-v0", "Pendulum-v1")
METHODS = ("pgpe", "openes", "snn", "sigmoid")
PEERS = ("pgpe", "openes")

# Training episodes per run, per environment: at least what gymnax-blines gives its ES on it
# (generations x 100 members x 20 episodes: CartPole-v1, Acrobot-v1, Pendulum-v1 100 generations =
# 200,000; MountainCarContinuous-v0 500 = 1,000,000; MountainCar-v0 1,000 = 2,000,000), and on
# Pendulum-v1 the 1,000,000 that covers the PGPE runs (290,000 to 600,000+).
DEFAULT_BUDGETS = {"CartPole-v1": 500_000, "Acrobot-v1": 500_000, "MountainCar-v0": 2_000_000,
                   "MountainCarContinuous-v0": 1_000_000, "Pendulum-v1": 1_000_000}

TRAIN_STREAM = 30_000_000  # + the run's seed: the stream of the peers' training starts (not the
#                            held-out VALIDATION_SEED + seed nor the test TEST_SEED + seed)

_EVOTORCH_FUNCTIONAL = "nnaisense/evotorch examples/notebooks/Functional_API/problem.ipynb (PGPE on CartPole-v1)"
_EVOTORCH_GYM = "nnaisense/evotorch examples/notebooks/Gym_Experiments_with_PGPE_and_CoSyNE.ipynb"
_EVOTORCH_GYMNE = "evotorch 0.6.1 evotorch/neuroevolution/gymne.py (GymNE: a Discrete(n) action space gets " \
                  "act_length = n outputs, and the action is np.argmax of them)"
_MAX_SPEED = 0.15  # _EVOTORCH_FUNCTIONAL: max_speed = 0.15
# the peers' heads, both of them: the value on a Discrete(n) port, then on a Box port
_OUTPUT = ("Discrete(n) ports: n logits, greedy (argmax k), fed as the centre of the port's bin k, "
           "-1 + (2k + 1) / n; Box ports: tanh x action_max, one output per action")
PGPE_SETTINGS: dict[str, dict] = {
    "popsize": {"value": 100, "source": _EVOTORCH_FUNCTIONAL + ": popsize = 100; the issue's measurement"},
    "episodes_per_member": {"value": 20, "source": "the issue's measurement (population 100 x 20 episodes); "
                                                   "EvoTorch's GymNE defaults to num_episodes=1"},
    "hidden_sizes": {"value": [16], "source": _EVOTORCH_FUNCTIONAL + ": 'Linear(obs_length, 16) >> Tanh() >> "
                                              "Linear(16, act_length)' (3-16-1 on Pendulum, as the issue measured)"},
    "hidden_activation": {"value": "tanh", "source": _EVOTORCH_FUNCTIONAL},
    "output": {"value": _OUTPUT,
               "source": _EVOTORCH_FUNCTIONAL + ": 'Linear(16, act_length)'; " + _EVOTORCH_GYMNE + "; the tanh on "
                         "Box ports (EvoTorch clips a linear output) and the bin centres are this benchmark's"},
    "observations": {"value": "normalised by the port's bounds, (obs - mid) / half, unclipped",
                     "source": "a fixed stand-in for " + _EVOTORCH_FUNCTIONAL + "'s observation_normalization=True"},
    "center_init": {"value": "zeros", "source": _EVOTORCH_FUNCTIONAL + ": center_init = problem.make_zeros(...)"},
    "max_speed": {"value": _MAX_SPEED, "source": _EVOTORCH_FUNCTIONAL + ": max_speed = 0.15"},
    "center_learning_rate": {"value": _MAX_SPEED / 2,
                             "source": "max_speed / 2: ClipUp's recommendation (Toklu et al. 2020), as "
                                       + _EVOTORCH_GYM + " sets it (center_learning_rate = max_speed / 2.); "
                                       + _EVOTORCH_FUNCTIONAL + " uses 0.75 * max_speed"},
    "momentum": {"value": 0.9, "source": _EVOTORCH_GYM + ": 'momentum': 0.9 (also ClipUp's default in EvoTorch)"},
    "radius_init": {"value": 15 * _MAX_SPEED, "source": _EVOTORCH_FUNCTIONAL + ": radius = max_speed * 15; "
                                                        + _EVOTORCH_GYM + ": max_speed = radius_init / 15"},
    "stdev_learning_rate": {"value": 0.1, "source": _EVOTORCH_FUNCTIONAL + " and " + _EVOTORCH_GYM},
    "stdev_max_change": {"value": 0.2, "source": _EVOTORCH_FUNCTIONAL + ": stdev_max_change = 0.2"},
    "ranking_method": {"value": "centered", "source": _EVOTORCH_FUNCTIONAL + ": ranking_method='centered'"},
    "optimizer": {"value": "clipup", "source": _EVOTORCH_FUNCTIONAL + ": optimizer='clipup'"},
    "symmetric": {"value": True, "source": _EVOTORCH_FUNCTIONAL + ": symmetric=True"},
}

_BLINES = "RobertTLange/gymnax-blines (commit 3f029d6, April 2023) "
_EVOSAX = "RobertTLange/evosax v.0.1.3 "


def _openes(yaml: str, sigma_init: float, lrate_init: float, note: str = "") -> dict[str, dict]:
    src = _BLINES + yaml + note
    return {
        "popsize": {"value": 100, "source": src + ": es_config.popsize"},
        "episodes_per_member": {"value": 20, "source": src + ": num_train_rollouts"},
        "hidden_sizes": {"value": [64, 64], "source": src + ": network_config num_hidden_units 64, num_hidden_layers 2"},
        "hidden_activation": {"value": "relu", "source": src + ": hidden_activation"},
        "output": {"value": _OUTPUT,
                   "source": _BLINES + "utils/models.py: num_output_units=env.num_actions (n logits of a "
                             "categorical it samples; greedy here, as " + _EVOTORCH_GYMNE + "); the tanh on Box "
                             "ports (gymnax-blines: a sampled Gaussian) and the bin centres are this benchmark's"},
        "observations": {"value": "raw", "source": "gymnax-blines feeds gymnax's observations unnormalised"},
        "sigma_init": {"value": sigma_init, "source": src + ": es_params.sigma_init"},
        "sigma_decay": {"value": 0.999, "source": src + ": es_params.sigma_decay"},
        "sigma_limit": {"value": 0.01, "source": src + ": es_params.sigma_limit"},
        "lrate_init": {"value": lrate_init, "source": src + ": opt_params.lrate_init"},
        "lrate_decay": {"value": 0.999, "source": src + ": opt_params.lrate_decay"},
        "lrate_limit": {"value": 0.001, "source": src + ": opt_params.lrate_limit"},
        "optimizer": {"value": "adam", "source": src + ": es_config.opt_name"},
        "beta_1": {"value": 0.99, "source": _EVOSAX + "evosax/utils/optimizer.py: Adam.params_opt"},
        "beta_2": {"value": 0.999, "source": _EVOSAX + "evosax/utils/optimizer.py: Adam.params_opt"},
        "eps": {"value": 1e-8, "source": _EVOSAX + "evosax/utils/optimizer.py: Adam.params_opt"},
        "centered_rank": {"value": True, "source": src + ": fitness_config.centered_rank"},
        "w_decay": {"value": 0.0, "source": src + ": fitness_config.w_decay"},
        "mean_init": {"value": "zeros", "source": _EVOSAX + "evosax/strategies/open_es.py: init_min = init_max = 0.0"},
        "antithetic": {"value": True, "source": _EVOSAX + "evosax/strategies/open_es.py: ask_strategy"},
    }


_NOT_OPENES = " (gymnax-blines runs SimpleGA on {env}: agents/{env}/es.yaml; OpenES settings taken from {yaml})"
OPENES_SETTINGS: dict[str, dict[str, dict]] = {
    "CartPole-v1": _openes("agents/CartPole-v1/es.yaml", 0.03, 0.04),
    "Acrobot-v1": _openes("agents/Acrobot-v1/es.yaml", 0.03, 0.04),
    "MountainCar-v0": _openes("agents/CartPole-v1/es.yaml", 0.03, 0.04, _NOT_OPENES.format(
        env="MountainCar-v0", yaml="the discrete-action configs, agents/CartPole-v1/es.yaml = agents/Acrobot-v1/es.yaml")),
    "MountainCarContinuous-v0": _openes("agents/Pendulum-v1/es.yaml", 0.05, 0.125, _NOT_OPENES.format(
        env="MountainCarContinuous-v0", yaml="the continuous-action config, agents/Pendulum-v1/es.yaml")),
    "Pendulum-v1": _openes("agents/Pendulum-v1/es.yaml", 0.05, 0.125),
}


def _values(settings: dict[str, dict]) -> dict:
    return {k: v["value"] for k, v in settings.items()}


def _median(values: list[float]) -> float:
    """The median, ``inf`` counting as a run that never got there."""
    return float(statistics.median(values)) if values else math.inf


# --- the peers ------------------------------------------------------------------------------
def _make_peer(method: str, env_id: str, task, seed: int) -> tuple[MLP, PGPE | OpenES, dict, bool]:
    """``(mlp, algorithm, settings values, raw observations)`` of a peer on ``task``."""
    if method == "pgpe":
        s = _values(PGPE_SETTINGS)
        mlp = MLP.for_task(task, s["hidden_sizes"], s["hidden_activation"])
        algo = PGPE(mlp.num_params, popsize=s["popsize"], center_learning_rate=s["center_learning_rate"],
                    max_speed=s["max_speed"], momentum=s["momentum"], radius_init=s["radius_init"],
                    stdev_learning_rate=s["stdev_learning_rate"], stdev_max_change=s["stdev_max_change"], seed=seed)
        return mlp, algo, s, False
    s = _values(OPENES_SETTINGS[env_id])
    mlp = MLP.for_task(task, s["hidden_sizes"], s["hidden_activation"])
    algo = OpenES(mlp.num_params, popsize=s["popsize"], sigma_init=s["sigma_init"], sigma_decay=s["sigma_decay"],
                  sigma_limit=s["sigma_limit"], lrate_init=s["lrate_init"], lrate_decay=s["lrate_decay"],
                  lrate_limit=s["lrate_limit"], beta_1=s["beta_1"], beta_2=s["beta_2"], eps=s["eps"],
                  w_decay=s["w_decay"], seed=seed)
    return mlp, algo, s, True


def run_peer(method: str, env_id: str, seed: int, budget_episodes: int, *, bar=None,
             validation_episodes: int = VALIDATION_EPISODES, test_episodes: int = TEST_EPISODES) -> dict:
    """One run of peer ``method`` ("pgpe" or "openes") on ``env_id`` with ``seed``, within
    ``budget_episodes`` training episodes: its record (module docstring; ``run_ours``' fields)."""
    task, threshold = gym_task(env_id)
    mlp, algo, s, raw = _make_peer(method, env_id, task, seed)
    P, E = int(s["popsize"]), int(s["episodes_per_member"])
    generations = budget_episodes // (P * E)
    if generations < 1:
        raise ReproduceError(f"--budget-episodes {budget_episodes} is less than one {method} generation on {env_id} "
                             f"({P} members x {E} episodes = {P * E})")
    train_stream = torch.Generator().manual_seed(TRAIN_STREAM + seed)
    val_seed, test_seed = VALIDATION_SEED + seed, TEST_SEED + seed
    rec: dict = {"env": env_id, "method": method, "seed": seed, "threshold": threshold,
                 "budget_episodes": budget_episodes, "history": [], "checks": [], "episodes": 0,
                 "validation_episodes": 0, "cpu_s": 0.0, "wall_s": 0.0, "generation": -1,
                 "episodes_to_threshold": None, "cpu_s_to_threshold": None, "wall_s_to_threshold": None,
                 "num_params": mlp.num_params, "mlp_sizes": list(mlp.sizes), "discrete": mlp.discrete}

    def held_out(candidates: torch.Tensor) -> torch.Tensor:
        rec["validation_episodes"] += candidates.shape[0] * validation_episodes
        return peer_returns(task, mlp, candidates, episodes=validation_episodes, seed=val_seed,
                            raw_observations=raw).mean(1)

    # one tiny rollout first, so the first generation's time does not include binding the plant
    peer_returns(task, mlp, torch.zeros(1, mlp.num_params), episodes=1, seed=0, raw_observations=raw)
    champion, best_ever, best_ever_fit, last_best = None, None, -math.inf, None
    for generation in range(1, generations + 1):
        cpu0, wall0 = time.process_time(), time.perf_counter()
        x = algo.ask()
        train_seed = int(torch.randint(0, 2**62, (1,), generator=train_stream))
        fitness = peer_returns(task, mlp, x, episodes=E, seed=train_seed, raw_observations=raw).mean(1)
        algo.tell(x, fitness)
        rec["episodes"] += P * E
        k = int(fitness.argmax())
        best = float(fitness[k])
        last_best = x[k].detach().clone()
        if best > best_ever_fit:
            best_ever, best_ever_fit = last_best, best
        rec["history"].append(best)
        rec["checks"].append(None)
        if best >= threshold:  # within reach: check the centre and the best member on the held-out episodes
            candidates = torch.stack([algo.center.detach().to(torch.float32), last_best.to(torch.float32)])
            scores = held_out(candidates)
            rec["checks"][-1] = float(scores.max())
            passed = scores >= threshold
            if bool(passed.any()):
                pick = int(torch.where(passed, scores, torch.full_like(scores, -math.inf)).argmax())
                champion, rec["champion_from"] = candidates[pick], ("centre", "best member")[pick]
                rec["champion_validation"] = float(scores[pick])
                rec["generation"], rec["episodes_to_threshold"] = generation, rec["episodes"]
        rec["cpu_s"] += time.process_time() - cpu0
        rec["wall_s"] += time.perf_counter() - wall0
        if bar is not None:
            bar.set_postfix_str(f"{env_id} {method} seed {seed}: gen {generation}/{generations} best {best:.4g}")
        if champion is not None:
            rec["cpu_s_to_threshold"], rec["wall_s_to_threshold"] = rec["cpu_s"], rec["wall_s"]
            break
    cpu0, wall0 = time.process_time(), time.perf_counter()
    if champion is None:  # the best on the held-out episodes of the final candidates
        candidates = torch.stack([algo.center.detach().to(torch.float32), last_best.to(torch.float32),
                                  best_ever.to(torch.float32)])
        names = ("final centre", "final best member", "best-ever member")
        scores = held_out(candidates)
        pick = int(scores.argmax())
        champion, rec["champion_from"], rec["champion_validation"] = candidates[pick], names[pick], float(scores[pick])
    test = peer_returns(task, mlp, champion.unsqueeze(0), episodes=test_episodes, seed=test_seed,
                        raw_observations=raw)[0]
    rec["cpu_s"] += time.process_time() - cpu0
    rec["wall_s"] += time.perf_counter() - wall0
    rec.update(generations=len(rec["history"]), reached=rec["generation"] > 0, test_episodes=test_episodes,
               test_mean=float(test.mean()), test_worst=float(test.min()), test_std=float(test.std(correction=0)))
    rec["test_reaches"] = rec["test_mean"] >= threshold
    rec["champion"] = champion.tolist()
    return rec


# --- ours ---------------------------------------------------------------------------------
def run_ours(controller: str, env_id: str, seed: int, budget_episodes: int) -> tuple[dict, dict]:
    """``snn-neat evolve env_id --controller controller --seed seed --episodes budget_episodes``
    (``tasks.studies.evolve_env.run_plan``): the run's record (``run_peer``'s fields) and the
    settings the library chose."""
    from tasks.studies.evolve_env import EvolvePlan, run_plan

    plan = EvolvePlan(env_id, controller, seeds=(seed,), episodes=budget_episodes)
    with tempfile.TemporaryDirectory(prefix="vs-es-") as folder:  # the checkpoint: not kept
        runs = run_plan(plan, folder, progress=False)
    r, built = runs.records[0], runs.built
    reached = r.confirmed_generation > 0
    rec = {"env": env_id, "method": controller, "seed": seed, "threshold": built.threshold,
           "budget_episodes": budget_episodes, "history": r.history, "checks": r.checks, "episodes": r.episodes,
           "validation_episodes": r.validation_episodes, "cpu_s": r.cpu_s, "wall_s": r.wall_s,
           "generation": r.confirmed_generation, "episodes_to_threshold": r.confirmed_episodes,
           "cpu_s_to_threshold": r.confirmed_cpu_s, "wall_s_to_threshold": r.confirmed_wall_s,
           "train_generation": r.train_generation, "champion_from": r.champion_from,
           "champion_validation": r.champion_validation, "generations": r.generations, "reached": reached,
           "test_episodes": r.test_episodes, "test_mean": r.test_mean, "test_worst": r.test_worst,
           "test_std": r.test_std, "test_reaches": r.test_mean is not None and r.test_mean >= built.threshold,
           "champion_hidden": r.champion_hidden, "champion_genes": r.champion_genes}
    rec["command"] = f"snn-neat evolve {env_id} --controller {controller} --seed {seed} --episodes {budget_episodes}"
    settings = {"pop_size": built.config.pop_size, "episodes_per_genome": built.episodes_per_genome,
                "generations": built.generations, "spec": repr(built.fitness.spec),
                "fresh_starts": bool(getattr(built.fitness, "fresh_starts", False)),
                "config": built.config.to_dict()}
    return rec, settings


# --- the table ----------------------------------------------------------------------------
def summarise(runs: list[dict]) -> list[dict]:
    """Per environment x method (in the runs' order): ``n``, ``test_reaches`` (runs whose test
    mean >= threshold), ``reached`` (on the held-out episodes), medians over all runs of training
    episodes and CPU seconds to the threshold (``inf``: the median run never reached it; JSON
    writes None) and of the test mean."""
    cells: dict[tuple[str, str], list[dict]] = {}
    for r in runs:
        cells.setdefault((r["env"], r["method"]), []).append(r)
    out = []
    for (env, method), rs in cells.items():
        tests = [r["test_mean"] for r in rs if r["test_mean"] is not None]
        out.append({
            "env": env, "method": method, "threshold": rs[0]["threshold"], "n": len(rs),
            "budget_episodes": rs[0]["budget_episodes"],
            "test_reaches": sum(bool(r["test_reaches"]) for r in rs),
            "reached": sum(bool(r["reached"]) for r in rs),
            "median_episodes_to_threshold": _median([r["episodes_to_threshold"] if r["reached"] else math.inf
                                                     for r in rs]),
            "median_cpu_s_to_threshold": _median([r["cpu_s_to_threshold"] if r["reached"] else math.inf for r in rs]),
            "median_test_mean": _median(tests) if tests else None,
            "seeds": [r["seed"] for r in rs],
        })
    return out


def _fmt(x: float | None, digits: int = 4) -> str:
    if x is None:
        return "-"
    return f"{x:,.0f}" if abs(x) >= 10 ** digits else f"{x:.{digits}g}"


def summary_markdown(summary: list[dict]) -> str:
    """The table of ``summarise``'s rows."""
    lines = ["| environment | threshold | method | test mean >= threshold | reached on held-out | "
             "median training episodes to threshold | median CPU-s to threshold | median test mean |",
             "|---|---:|---|---:|---:|---:|---:|---:|"]
    for row in summary:
        over = f"> {row['budget_episodes']:,}"
        episodes = row["median_episodes_to_threshold"]
        cpu = row["median_cpu_s_to_threshold"]
        lines.append(f"| {row['env']} | {_fmt(row['threshold'])} | {row['method']} | {row['test_reaches']}/{row['n']} | "
                     f"{row['reached']}/{row['n']} | {over if math.isinf(episodes) else f'{episodes:,.0f}'} | "
                     f"{'never' if math.isinf(cpu) else f'{cpu:.1f}'} | {_fmt(row['median_test_mean'])} |")
    return "\n".join(lines) + "\n"


def _jsonable(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def _write(out: Path, results: dict) -> None:
    summary = summarise(results["runs"])
    results["summary"] = summary
    header = (f"# Classic control: NEAT against evolution strategies\n\n"
              f"`{results['command']}`  \n{results['created']}, {results['machine']}, torch threads "
              f"{results['threads']}; seeds {results['seeds']}; held-out {results['validation_episodes']} and test "
              f"{results['test_episodes']} episodes per check. Medians over all runs of an environment x method; a run "
              f"that never reached the threshold counts as never (\"> budget\" where the median run did not).\n\n")
    atomic_write_bytes(out / "summary.md", (header + summary_markdown(summary)).encode())
    atomic_write_bytes(out / "results.json", json.dumps(_jsonable(results), indent=1).encode())


# --- the command --------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=list(ENVIRONMENTS), choices=ENVIRONMENTS, metavar="ENV",
                   help=f"environments (default: all five: {' '.join(ENVIRONMENTS)})")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS, metavar="METHOD",
                   help=f"methods (default: {' '.join(METHODS)})")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4], help="seeds (default: 0 1 2 3 4)")
    p.add_argument("--budget-episodes", type=int, default=None,
                   help="training episodes per run, every environment (default: per environment, "
                        + ", ".join(f"{k} {v:,}" for k, v in DEFAULT_BUDGETS.items()) + ")")
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    p.add_argument("--out", default="results/classic_control_vs_es", help="output folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar, no table printed")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.budget_episodes is not None and args.budget_episodes < 1:
        print("--budget-episodes must be a positive number of episodes", file=sys.stderr)
        return 2
    if args.threads < 1:
        print("--threads must be at least 1", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    budgets = {env: args.budget_episodes or DEFAULT_BUDGETS[env] for env in args.envs}
    import evotorch

    argv_text = sys.argv[1:] if argv is None else argv
    results: dict = {
        "command": shlex.join(["python", "benchmarks/classic_control_vs_es.py", *argv_text]),
        "created": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": f"{platform.machine()} {platform.processor() or ''} {os.cpu_count()} CPUs, "
                   f"{platform.system()} {platform.release()}, Python {platform.python_version()}".replace("  ", " "),
        "versions": {"torch": torch.__version__, "evotorch": evotorch.__version__},
        "threads": args.threads, "envs": args.envs, "methods": args.methods, "seeds": args.seeds,
        "budget_episodes": budgets, "validation_episodes": VALIDATION_EPISODES, "test_episodes": TEST_EPISODES,
        "seeding": {"validation": f"VALIDATION_SEED + seed = {VALIDATION_SEED} + seed",
                    "test": f"TEST_SEED + seed = {TEST_SEED} + seed",
                    "peer_training": f"each generation's starts seeded from a stream seeded by {TRAIN_STREAM} + seed; "
                                     "the algorithm's own sampling seeded by seed"},
        "settings": {"pgpe": PGPE_SETTINGS, "openes": {env: OPENES_SETTINGS[env] for env in args.envs}, "ours": {}},
        "runs": [],
    }
    plan = [(env, method, seed) for env in args.envs for method in args.methods for seed in args.seeds]
    from tqdm.auto import tqdm

    bar = tqdm(total=len(plan), unit="run", desc="runs", disable=args.quiet, file=sys.stderr)
    try:
        for env, method, seed in plan:
            bar.set_postfix_str(f"{env} {method} seed {seed}")
            if method in PEERS:
                rec = run_peer(method, env, seed, budgets[env], bar=None if args.quiet else bar)
            else:
                rec, settings = run_ours(method, env, seed, budgets[env])
                results["settings"]["ours"].setdefault(env, {})[method] = settings
            results["runs"].append(rec)
            _write(out, results)
            bar.update(1)
    except ReproduceError as exc:
        bar.close()
        print(f"classic_control_vs_es: {exc}", file=sys.stderr)
        return 2
    bar.close()
    if not args.quiet:
        print(summary_markdown(results["summary"]))
    print(f"wrote {out / 'summary.md'} and {out / 'results.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
