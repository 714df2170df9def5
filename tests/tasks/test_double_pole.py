"""Double-pole balancing against an independent float64 transcription of ESP's C code."""

import math

import pytest
import torch

from evolution import NEAT, TaskFitness, spiking_config
from evolution.phenotype import SpikingSpec
from tasks.double_pole import DoublePoleParams, DoublePoleTask, double_pole_failed, double_pole_step

# ESP / NEAT 2002's constants, written out again here on purpose (not imported).
MUP, GRAVITY, MASSCART, M1, L1, M2, L2, TAU = 0.000002, -9.8, 1.0, 0.1, 0.5, 0.01, 0.05, 0.01
THIRTY_SIX = 0.628329


def _esp_derivs(force, st):
    c1, s1, c2, s2 = math.cos(st[2]), math.sin(st[2]), math.cos(st[4]), math.sin(st[4])
    gs1, gs2 = GRAVITY * s1, GRAVITY * s2
    ml1, ml2 = L1 * M1, L2 * M2
    t1, t2 = MUP * st[3] / ml1, MUP * st[5] / ml2
    fi1 = (ml1 * st[3] * st[3] * s1) + (0.75 * M1 * c1 * (t1 + gs1))
    fi2 = (ml2 * st[5] * st[5] * s2) + (0.75 * M2 * c2 * (t2 + gs2))
    mi1, mi2 = M1 * (1 - (0.75 * c1 * c1)), M2 * (1 - (0.75 * c2 * c2))
    xacc = (force + fi1 + fi2) / (mi1 + mi2 + MASSCART)
    return [st[1], xacc, st[3], -0.75 * (xacc * c1 + gs1 + t1) / L1, st[5], -0.75 * (xacc * c2 + gs2 + t2) / L2]


def _esp_rk4(force, y):
    hh, h6 = TAU * 0.5, TAU / 6.0
    dydx = _esp_derivs(force, y)
    yt = [y[i] + hh * dydx[i] for i in range(6)]
    dyt = _esp_derivs(force, yt)
    yt = [y[i] + hh * dyt[i] for i in range(6)]
    dym = _esp_derivs(force, yt)
    yt = [y[i] + TAU * dym[i] for i in range(6)]
    dym = [dym[i] + dyt[i] for i in range(6)]
    dyt = _esp_derivs(force, yt)
    return [y[i] + h6 * (dydx[i] + dyt[i] + 2.0 * dym[i]) for i in range(6)]


def _esp_perform(force, state):
    for _ in range(2):  # NEAT's performAction: two RK4 steps per network activation
        state = _esp_rk4(force, state)
    return state


def _esp_outside(st):
    return abs(st[0]) > 2.4 or abs(st[2]) > THIRTY_SIX or abs(st[4]) > THIRTY_SIX


def test_trajectories_match_esp_to_rounding():
    g = torch.Generator().manual_seed(0)
    starts = torch.zeros(5, 6, dtype=torch.float64)
    starts[:, 2] = torch.tensor([0.07, -0.05, 0.0, 0.1, 0.02], dtype=torch.float64)
    starts[:, 1] = torch.rand(5, generator=g, dtype=torch.float64) - 0.5
    forces = (torch.rand(300, 5, generator=g, dtype=torch.float64) - 0.5) * 20
    ours = starts.clone()
    ref = [row.tolist() for row in starts]
    worst = 0.0
    for t in range(300):
        ours = double_pole_step(ours, forces[t])
        ref = [_esp_perform(float(forces[t, b]), ref[b]) for b in range(5)]
        worst = max(worst, float((ours - torch.tensor(ref, dtype=torch.float64)).abs().max()))
    assert worst < 1e-9
    assert float(ours[:, [2, 4]].abs().max()) > 0.5  # random pushes made the poles move a lot


def _esp_damping_fitness(forces, terms=4):
    """NEAT 2002's non-Markov evaluation (experiments.cpp), for a fixed sequence of forces; ``terms=6``
    adds the short pole's |theta2| + |theta2_dot| to each step's damping term."""
    state = [0.0, 0.0, 0.07, 0.0, 0.0, 0.0]
    jiggle, balanced = [], 0
    for stepnum in range(1, 1001):
        state = _esp_perform(forces[stepnum - 1], state)
        jiggle.append(sum(abs(v) for v in state[:terms]))
        if _esp_outside(state):
            break
        balanced += 1
    if balanced > 100:
        return 0.1 * (balanced / 1000.0) + 0.9 * (0.75 / sum(jiggle[balanced - 100 : balanced])), balanced
    return 0.1 * (balanced / 1000.0), balanced


def _lqr_gains():
    """An LQR law for ESP's plant linearised at rest (finite differences; Q = I, R = 1)."""
    import numpy as np
    from scipy.linalg import solve_continuous_are

    eps, rest = 1e-6, np.array(_esp_derivs(0.0, [0.0] * 6))
    A = np.stack([(np.array(_esp_derivs(0.0, [eps if k == i else 0.0 for k in range(6)])) - rest) / eps
                  for i in range(6)], 1)
    B = ((np.array(_esp_derivs(eps, [0.0] * 6)) - rest) / eps).reshape(6, 1)
    return (B.T @ solve_continuous_are(A, B, np.eye(6), np.eye(1)))[0].tolist()


def _lqr_forces(off_after):
    """Forces of the LQR law (+-10 N) on ESP's plant, switched off after ``off_after`` steps."""
    gains, state, forces = _lqr_gains(), [0.0, 0.0, 0.07, 0.0, 0.0, 0.0], []
    for t in range(1000):
        f = 0.0 if t >= off_after else max(-10.0, min(10.0, -sum(k * x for k, x in zip(gains, state, strict=True))))
        forces.append(f)
        state = _esp_perform(f, state)
    return forces


@pytest.mark.parametrize("c_kernels", ["1", "0"])
@pytest.mark.parametrize("off_after, outcome", [(1000, "balances"), (300, "falls late"), (0, "falls early")])
@pytest.mark.parametrize("fitness, terms", [("damping", 4), ("damping-both-poles", 6)])
def test_damping_fitness_is_gruaus(fitness, terms, off_after, outcome, c_kernels, monkeypatch):
    monkeypatch.setenv("SNN_NEAT_C_KERNELS", c_kernels)
    forces = _lqr_forces(off_after)
    expected, balanced = _esp_damping_fitness(forces, terms)
    task = DoublePoleTask.without_velocities(fitness=fitness)
    state = task.reset(1, None)
    total, steps = 0.0, 0
    for t in range(1000):
        state, reward, failed = task.step(state, torch.tensor([[forces[t]]], dtype=torch.float64))
        total += float(reward[0])
        if bool(failed[0]):
            break
        steps += 1
    assert steps == balanced
    assert total == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert {"balances": balanced == 1000, "falls late": 300 <= balanced < 1000,
            "falls early": balanced < 100}[outcome]


def test_a_plant_held_at_rest_scores_a_finite_damping_fitness_on_both_paths():
    """Started exactly at rest and never pushed, the damping term's sum is 0: the fitness is
    floored (DAMPING_TOTAL_FLOOR), not 1/0, and the native step agrees."""
    from evolution.kernels.native_plant import native_plant
    from tasks.double_pole import DAMPING_TOTAL_FLOOR

    task = DoublePoleTask.without_velocities(max_steps=150)
    plant = native_plant(task, torch.float64)
    assert plant is not None
    state = task.starts(torch.zeros(2, 6, dtype=torch.float64))
    state[1, 2] = 0.01  # a second row that moves: its fitness is not floored
    paid, ref_paid = torch.zeros(2, dtype=torch.float64), torch.zeros(2, dtype=torch.float64)
    ours = ref = state
    for _ in range(150):
        ours, reward, _ = plant.step(ours, torch.zeros(2, 1, dtype=torch.float64))
        ref, ref_reward, failed = task.step(ref, torch.zeros(2, 1, dtype=torch.float64))
        paid, ref_paid = paid + reward, ref_paid + ref_reward
    assert not bool(failed[0]) and torch.equal(ours, ref) and torch.equal(paid, ref_paid)
    assert paid[0].item() == 0.1 * 150 / 1000 + 0.9 * (0.75 / DAMPING_TOTAL_FLOOR)
    assert torch.isfinite(paid).all() and paid[1] < 1.0


@pytest.mark.parametrize("velocities, fitness", [(True, "steps"), (False, "damping"), (False, "damping-both-poles")])
def test_the_native_step_is_the_torch_step_bit_for_bit(velocities, fitness):
    """The native step (tasks/csrc/double_pole.c) against the torch definition, step by step from
    all 625 generalisation starts under the LQR law with noise (a few start states fail, most
    balance 600 steps): the same bits (sin and cos from portable_math, sums in slot order)."""
    from evolution.kernels.native_plant import native_plant
    from tasks.studies.generalization import generalization_starts

    task = DoublePoleTask(velocities=velocities, fitness=fitness, max_steps=600)
    plant = native_plant(task, torch.float64)
    assert plant is not None, "the native step must build here (CI has a C compiler)"
    gains = torch.tensor(_lqr_gains(), dtype=torch.float64)
    g = torch.Generator().manual_seed(1)
    state = task.starts(generalization_starts())
    alive = torch.ones(625, dtype=torch.bool)
    paid = torch.zeros(625, dtype=torch.float64)
    for _ in range(600):
        force = (-(state[:, :6] @ gains) + torch.randn(625, generator=g, dtype=torch.float64)).clamp(-10, 10)
        ours, reward, failed = plant.step(state, force.unsqueeze(1))
        ref, ref_reward, ref_failed = task.step(state, force.unsqueeze(1))
        assert torch.equal(failed, ref_failed)
        assert torch.equal(ours, ref)
        assert torch.equal(reward, ref_reward)
        assert torch.equal(plant.observe(state), task.observe(state))
        paid += torch.where(alive, reward, 0.0)
        alive &= ~failed
        state = ref
    assert 0 < int(alive.sum()) < 625
    if not velocities:
        assert bool((paid[alive] > 0.06).all())  # the 600th step paid Gruau's fitness: 0.1 * 600 / 1000 + a damping term


def test_tasks_declare_the_published_setups_and_refuse_bad_ones():
    dpv, dpnv = DoublePoleTask.with_velocities(), DoublePoleTask.without_velocities()
    assert (dpv.observation_size, dpv.fitness, dpv.max_steps) == (6, "steps", 100_000)
    assert (dpnv.observation_size, dpnv.fitness, dpnv.max_steps) == (3, "return", 1000)
    assert dpv.control_period_s == pytest.approx(0.02)
    start = dpnv.reset(3, None)
    assert start.shape == (3, 107) and bool((start[:, 2] == 0.07).all())
    assert dpnv.observe(start).tolist() == [[0.0, 0.07, 0.0]] * 3
    assert bool(double_pole_failed(torch.tensor([[0.0, 0, 0, 0, 0.63, 0]], dtype=torch.float64)).all())
    with pytest.raises(ValueError, match="fitness must be"):
        DoublePoleTask(velocities=True, fitness="jiggle")
    with pytest.raises(ValueError, match="theta1_0"):
        DoublePoleTask(velocities=True, theta1_0=1.0)
    with pytest.raises(ValueError, match="DoublePoleParams.pole2_mass"):
        DoublePoleParams(pole2_mass=-0.01)


def test_dpnv_evolves_through_the_public_seam():
    task = DoublePoleTask.without_velocities()
    cfg = spiking_config(num_inputs=3, num_outputs=1, pop_size=24, max_hidden=4)
    fitness = TaskFitness(task, cfg, "snn")
    neat = NEAT(cfg, seeds=[0])
    first = fitness(neat.ask())
    result = neat.run(fitness, generations=4)
    assert first.shape == (1, 24) and bool((first > 0).all())  # every genome balances a few steps
    assert float(result.best_fitness[0]) > float(first.max())


def test_generalization_grid_and_the_champion_test():
    from tasks.studies.double_pole import champion_solves
    from tasks.studies.generalization import GRUAU_RANGES, balanced_steps, generalization_starts

    grid = generalization_starts()
    assert grid.shape == (625, 6) and bool((grid[:, 4:] == 0).all())
    for k, a in enumerate(GRUAU_RANGES):  # each variable at 5 levels, +-0.9 of its range at the extremes
        assert sorted(set(grid[:, k].tolist())) == pytest.approx([a * v for v in (-0.9, -0.5, 0.0, 0.5, 0.9)])
    cfg = spiking_config(num_inputs=3, num_outputs=1, pop_size=16, max_hidden=4)
    neat = NEAT(cfg, seeds=[3, 4])
    neat.run(TaskFitness(DoublePoleTask.without_velocities(), cfg, SpikingSpec()), 3)  # the study functions read "snn" so
    genomes = neat.ask()
    steps = balanced_steps(genomes, cfg, max_steps=60)[..., 0]  # [R, P] from the standard start
    alone = balanced_steps(genomes.select_runs([1]), cfg, max_steps=60)[0, :, 0]
    assert torch.equal(alone, steps[1])  # a genome's balance does not depend on its batch
    fitness = steps.to(torch.float64)
    solved = champion_solves(genomes, fitness, cfg, long_steps=60, min_general=0)
    assert solved.shape == (2, 16) and int(solved.sum(-1).max()) <= 1  # at most the champion, per run
    champion_steps = steps.gather(1, fitness.argmax(-1, keepdim=True))[:, 0]
    assert torch.equal(solved.any(-1), champion_steps >= 60)
    never = champion_solves(genomes, fitness, cfg, long_steps=60, min_general=626)  # more starts than exist
    assert not bool(never.any())


def test_observation_bounds_set_the_scaling_and_the_champion_test_uses_them():
    from evolution.phenotype import SigmoidSpec
    from tasks.studies.generalization import balanced_steps

    narrow = DoublePoleTask.with_velocities(observation_bounds=(2.4, 2.0, 0.3, 2.0, 0.3, 4.0), max_steps=300)
    assert narrow.observation_high == (2.4, 2.0, 0.3, 2.0, 0.3, 4.0) and narrow.observation_low[2] == -0.3
    for bad in [(1.0, 2.0), (2.4, 2.0, 0.0, 2.0, 0.3, 4.0), (2.4, 2.0, float("nan"), 2.0, 0.3, 4.0)]:
        with pytest.raises(ValueError, match="observation_bounds"):
            DoublePoleTask.with_velocities(observation_bounds=bad)
    cfg = spiking_config(6, pop_size=12, num_bias=1, sigma_mutate_rate=0.0, compatibility_sigma_coefficient=0.0)
    genomes = NEAT(cfg, seeds=[3]).ask()
    fit = TaskFitness(narrow, cfg, SigmoidSpec())(genomes)
    steps = balanced_steps(genomes, cfg, SigmoidSpec(), velocities=True, max_steps=300, task=narrow)
    default = balanced_steps(genomes, cfg, SigmoidSpec(), velocities=True, max_steps=300)
    assert torch.equal(steps[..., 0].to(fit.dtype), fit)  # the test sees what evolution saw
    assert not torch.equal(steps, default)  # and the bounds change what the networks do
