"""What it takes to evolve Pendulum-v1's swing-up (issue 32, item 6): one setting per call.

    python -m experiments.pendulum_swing_up --kind snn --coding signed --window 1 --episodes 16 --generations 60
    python -m experiments.pendulum_swing_up --kind sigmoid --velocity --episodes 64 --generations 150

Evolves on ``tasks.pendulum.PendulumTask`` (gymnasium's Pendulum-v1; ``--velocity`` observes
theta_dot, else only cos and sin, the user's plant of the issue) with fresh starts every
generation, one thread, then tests two champions per run on 50 fresh starts (seed 12345): the
best-ever genome (chosen on its noisy training fitness) and the final population's best on 50
validation starts (seed 999). It also says in how many test episodes the champion ends
upright (cos theta > 0.95 over the last 20 steps) and how many turn over twice or more.
Prints one JSON line.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import torch

from evolution import NEAT, SigmoidSpec, SpikingSpec, TaskFitness, make_controller, rollout, task_config
from tasks.pendulum import PendulumTask

TEST_SEED, VALIDATION_SEED, TEST_EPISODES = 12345, 999, 50


class StratifiedPendulum(PendulumTask):
    """Training starts stratified in angle: of ``n`` starts, the k-th has theta uniform in the
    k-th of ``n`` equal arcs of [-pi, pi) (theta_dot as gymnasium's, uniform in [-1, 1)). Each
    start is still uniform over the circle, but a genome's mean return no longer depends on how
    many of its starts happened to hang still: less noise for the same episodes."""

    def reset(self, batch, generator, *, device="cpu", dtype=torch.float32):
        state = super().reset(batch, generator, device="cpu", dtype=torch.float64)
        arc = 2.0 * math.pi / batch
        theta = -math.pi + arc * (torch.arange(batch, dtype=torch.float64) + (state[:, 0] + math.pi) / (2 * math.pi))
        return torch.stack([theta, state[:, 1]], -1).to(device=device, dtype=dtype)


def _test(task, genomes, cfg, spec) -> dict:
    result = rollout(task, make_controller(genomes, cfg, task, spec), episodes=TEST_EPISODES, seed=TEST_SEED,
                     record=True)
    theta = result.trace["state"][:, :, 0].view(-1, genomes.num_runs, TEST_EPISODES)  # [T, runs, episodes]
    upright = (torch.cos(theta[-20:]).mean(0) > 0.95).sum(-1)
    turns = ((theta[-1] - theta[0]).abs() / (2 * math.pi)).floor()
    return {"mean": [round(float(v), 1) for v in result.returns.mean(-1)],
            "upright": upright.tolist(), "two_turns": (turns >= 2).sum(-1).tolist()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--kind", choices=("snn", "sigmoid"), default="snn")
    p.add_argument("--velocity", action="store_true", help="observe theta_dot (gymnasium's observation)")
    p.add_argument("--coding", choices=("unit", "signed", "push_pull"), default="signed")
    p.add_argument("--window", type=int, default=1, help="NEAT-SNN's rate window (control steps of 50 ms)")
    p.add_argument("--episodes", type=int, default=16, help="fresh episodes per genome per generation")
    p.add_argument("--generations", type=int, default=60)
    p.add_argument("--pop", type=int, default=150)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--fixed-starts", action="store_true", help="the same starts every generation instead")
    p.add_argument("--cfg", default="{}", help="NEATConfig overrides as JSON, e.g. '{\"node_add_prob\": 0.2}'")
    p.add_argument("--stratified", action="store_true", help="training starts stratified in angle (StratifiedPendulum)")
    p.add_argument("--rest-relative", action="store_true", help="NEAT-SNN: rates relative to rest")
    p.add_argument("--control-period", type=float, default=0.05,
                   help="network time per control step (s; NEAT-SNN runs it in 0.5 ms substeps); the plant "
                        "always advances 0.05 s")
    a = p.parse_args()
    torch.set_num_threads(1)
    task = PendulumTask(observe_velocity=a.velocity, control_period_s=a.control_period)
    spec = (SpikingSpec(input_coding=a.coding, rate_window_steps=a.window, rest_relative=a.rest_relative)
            if a.kind == "snn" else SigmoidSpec(input_coding=a.coding))
    cfg = task_config(task, spec, **{"pop_size": a.pop, "max_hidden": 16, **json.loads(a.cfg)})
    train_task = (StratifiedPendulum(observe_velocity=a.velocity, control_period_s=a.control_period)
                  if a.stratified else task)
    fitness = TaskFitness(train_task, cfg, spec, episodes=a.episodes, seed=7, fresh_starts=not a.fixed_starts)
    t0 = time.perf_counter()
    neat = NEAT(cfg, seeds=a.seeds)
    result = neat.run(fitness, generations=a.generations)
    evolution_s = time.perf_counter() - t0
    final = neat.ask()
    validation = rollout(task, make_controller(final, cfg, task, spec), episodes=TEST_EPISODES,
                         seed=VALIDATION_SEED).returns.mean(-1).view(len(a.seeds), a.pop)
    validated = final.gather(validation.argmax(1, keepdim=True))
    print(json.dumps({"settings": vars(a), "train_best": [round(float(v), 1) for v in result.best_fitness],
                      "test_best_ever": _test(task, result.best_genomes, cfg, spec),
                      "test_validated": _test(task, validated, cfg, spec), "evolution_s": round(evolution_s, 1)}))


if __name__ == "__main__":
    main()
