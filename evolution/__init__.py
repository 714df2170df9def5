"""NEAT on population tensors, and the task seam every controller runs on.

    from evolution import NEAT, Task, TaskFitness, task_config
    neat = NEAT(task_config(my_task, "snn"), seeds=range(8))
    result = neat.run(TaskFitness(my_task, neat.config, "snn"), generations=100)
"""

from evolution.checkpoint import CheckpointError
from evolution.config import ConfigError, NEATConfig
from evolution.genome_io import load_genome, save_genome, to_networkx
from evolution.neat import NEAT, FitnessError, NEATResult
from evolution.phenotype import (
    SigmoidController,
    SigmoidSpec,
    SpikingController,
    SpikingSpec,
    make_controller,
    rest_rate_hz,
    sigmoid_config,
    spiking_config,
    task_config,
)
from evolution.population import Genomes, check_invariants, random_genomes
from evolution.reporters import BaseReporter, Checkpointer, StatisticsReporter, StdOutReporter, TqdmReporter
from evolution.rollout import RolloutResult, TaskFitness, episode_starts, evaluate, fresh_starts, rollout
from evolution.task import NativeStep, Task, TaskError

__all__ = [
    "NEAT", "NEATConfig", "NEATResult", "Genomes", "ConfigError", "CheckpointError", "FitnessError",
    "BaseReporter", "Checkpointer", "StatisticsReporter", "StdOutReporter", "TqdmReporter",
    "check_invariants", "random_genomes", "load_genome", "save_genome", "to_networkx",
    "Task", "TaskError", "NativeStep", "TaskFitness", "RolloutResult", "rollout", "evaluate", "episode_starts", "fresh_starts",
    "SpikingSpec", "SigmoidSpec", "SpikingController", "SigmoidController", "make_controller", "rest_rate_hz", "spiking_config",
    "sigmoid_config", "task_config",
]
