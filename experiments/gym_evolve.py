"""NEAT-SNN on gymnasium environments through ``tasks.gym_adapter.GymTask``: a discrete-action and a
continuous-action environment, several seeded runs each, a table of what the champions reach.

    python -m experiments.gym_evolve                      # CartPole-v1 and Pendulum-v1, seeds 0-3
    python -m experiments.gym_evolve --seeds 8 --generations 30

Each run evolves a population with the paper's spiking controller defaults (``SpikingSpec()``,
``spiking_config``), scored on ``--episodes`` seeded episodes (the same ones every generation);
the champion is then tested on 20 fresh seeded episodes. CartPole-v1 pays 1 per step up to
500; Pendulum-v1 pays minus a cost (0 is best; about -1200 to -1500 for doing nothing).
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from evolution import NEAT, TaskFitness, make_controller, rollout, spiking_config
from tasks.gym_adapter import GymTask

ENVIRONMENTS = {
    "CartPole-v1": dict(observation_bounds=((-2.4, -3.0, -0.21, -3.5), (2.4, 3.0, 0.21, 3.5))),
    "Pendulum-v1": dict(control_period_s=0.05),
}


def evolve(env_id: str, seed: int, *, pop_size: int, generations: int, episodes: int) -> dict:
    task = GymTask(env_id, **ENVIRONMENTS[env_id])
    cfg = spiking_config(num_inputs=task.observation_size, num_outputs=task.action_size, pop_size=pop_size,
                         max_hidden=6)
    fitness = TaskFitness(task, cfg, "snn", episodes=episodes, seed=seed)
    neat = NEAT(cfg, seeds=[seed])
    t0 = time.perf_counter()
    first = float(fitness(neat.ask()).max())
    result = neat.run(fitness, generations=generations)
    test = rollout(task, make_controller(result.best_genomes, cfg, task), episodes=20, seed=10_000 + seed)
    return {"env": env_id, "seed": seed, "first_best": first, "champion": float(result.best_fitness[0]),
            "test_mean": float(test.returns.mean()), "test_min": float(test.returns.min()),
            "seconds": time.perf_counter() - t0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--generations", type=int, default=15)
    parser.add_argument("--pop-size", type=int, default=50)
    parser.add_argument("--episodes", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"population {args.pop_size}, {args.generations} generations, {args.episodes} training episodes, "
          f"seeds 0-{args.seeds - 1}; champion tested on 20 fresh episodes")
    print("| environment | seed | first generation's best | champion (training) | test mean | test worst | s |")
    print("|---|---|---|---|---|---|---|")
    for env_id in ENVIRONMENTS:
        rows = [evolve(env_id, s, pop_size=args.pop_size, generations=args.generations, episodes=args.episodes)
                for s in range(args.seeds)]
        for r in rows:
            print(f"| {env_id} | {r['seed']} | {r['first_best']:.1f} | {r['champion']:.1f} | {r['test_mean']:.1f} | "
                  f"{r['test_min']:.1f} | {r['seconds']:.0f} |")
        print(f"| {env_id} | median | | {statistics.median(r['champion'] for r in rows):.1f} | "
              f"{statistics.median(r['test_mean'] for r in rows):.1f} | | |")


if __name__ == "__main__":
    main()
