"""NEAT on population tensors (see DESIGN.md, "Population as tensors").

    from evolution import NEAT, NEATConfig, StdOutReporter
    neat = NEAT(NEATConfig(num_inputs=2, num_outputs=1), seeds=range(8))
    result = neat.run(fitness_fn, generations=100, fitness_target=3.9)
"""

from evolution.checkpoint import CheckpointError
from evolution.config import ConfigError, NEATConfig
from evolution.genome_io import load_genome, save_genome, to_networkx
from evolution.neat import NEAT, FitnessError, NEATResult
from evolution.phenotype import SigmoidNetworks, SpikingNetworks
from evolution.population import Genomes, check_invariants
from evolution.reporters import BaseReporter, Checkpointer, StatisticsReporter, StdOutReporter, TqdmReporter

__all__ = [
    "NEAT", "NEATConfig", "NEATResult", "Genomes", "ConfigError", "CheckpointError", "FitnessError",
    "BaseReporter", "Checkpointer", "StatisticsReporter", "StdOutReporter", "TqdmReporter",
    "SigmoidNetworks", "SpikingNetworks", "check_invariants", "load_genome", "save_genome", "to_networkx",
]
