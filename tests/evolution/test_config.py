import dataclasses

import pytest

from evolution.config import ConfigError, NEATConfig

NEAT_PYTHON_INI = """
[NEAT]
fitness_criterion     = max
fitness_threshold     = 3.9
pop_size              = 150
reset_on_extinction   = False

[DefaultGenome]
num_inputs              = 2
num_hidden              = 0
num_outputs             = 1
initial_connection      = full_direct
feed_forward            = True
compatibility_disjoint_coefficient = 1.0
compatibility_weight_coefficient   = 0.5
conn_add_prob           = 0.5
node_add_prob           = 0.2
activation_default      = sigmoid
bias_mutate_rate        = 0.7
weight_max_value        = 30
weight_min_value        = -30
weight_mutate_power     = 0.5
enabled_mutate_rate     = 0.01

[DefaultSpeciesSet]
compatibility_threshold = 3.0

[DefaultStagnation]
species_fitness_func = max
max_stagnation       = 20
species_elitism      = 2

[DefaultReproduction]
elitism            = 2
survival_threshold = 0.2
"""


def test_defaults_are_the_papers():
    cfg = NEATConfig()
    assert cfg.pop_size == 150 and cfg.node_add_prob == 0.03 and cfg.conn_add_prob == 0.1
    assert cfg.survival_threshold == 0.2 and cfg.elitism_min_species_size == 6  # "more than 5"
    assert not cfg.initial_self_loops


def test_reads_a_neat_python_ini(tmp_path):
    path = tmp_path / "xor.ini"
    path.write_text(NEAT_PYTHON_INI)
    cfg = NEATConfig.from_ini(path)
    assert cfg.fitness_threshold == 3.9 and cfg.feed_forward is True and cfg.reset_on_extinction is False
    assert cfg.conn_add_prob == 0.5 and cfg.node_add_prob == 0.2 and cfg.max_stagnation == 20
    assert cfg.compatibility_weight_coefficient == 0.5 and cfg.weight_max_value == 30 and cfg.elitism == 2
    assert NEATConfig.from_ini(path, pop_size=50).pop_size == 50


@pytest.mark.parametrize("edit, match", [
    (("node_add_prob           = 0.2", "node_add_prob = lots"), r"\[DefaultGenome\] node_add_prob must be a number"),
    (("node_add_prob           = 0.2", "node_add_prob = 2.0"), r"node_add_prob must be in \[0, 1\]"),
    (("num_hidden              = 0", "num_hidden = 3"), "num_hidden must be 0"),
    (("feed_forward            = True", "feed_forward = maybe"), "feed_forward must be true or false"),
    (("max_stagnation       = 20", "max_stagnation = 20\nfavourite_colour = blue"), "favourite_colour is not a NEATConfig field"),
])
def test_bad_ini_values_name_file_section_and_key(tmp_path, edit, match):
    path = tmp_path / "bad.ini"
    path.write_text(NEAT_PYTHON_INI.replace(*edit))
    with pytest.raises(ConfigError, match=match):
        NEATConfig.from_ini(path)


def test_unreadable_ini(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        NEATConfig.from_ini(tmp_path / "missing.ini")
    (tmp_path / "junk.ini").write_text("no sections here")
    with pytest.raises(ConfigError, match="junk.ini"):
        NEATConfig.from_ini(tmp_path / "junk.ini")


def test_cross_field_checks():
    with pytest.raises(ConfigError, match="weight_min_value"):
        NEATConfig(weight_min_value=5.0, weight_max_value=1.0)
    with pytest.raises(ConfigError, match="sigma_min_value"):
        NEATConfig(sigma_min_value=2.0, sigma_max_value=1.0)
    assert dataclasses.replace(NEATConfig(), pop_size=10).pop_size == 10


def test_neat121_options_default_off_and_read_from_ini(tmp_path):
    # NEAT C++ 1.2.1's mechanisms (evolution.neat121): off by default, any INI can turn them on.
    cfg = NEATConfig()
    assert (cfg.stagnant_fitness_factor, cfg.obliterate_interval, cfg.population_stagnation, cfg.mate_only_prob,
            cfg.crossover_average_prob, cfg.recur_only_prob, cfg.toggle_enable_prob, cfg.gene_reenable_prob) == (
        0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert not (cfg.mutation_exclusive or cfg.weight_mutate_neatc or cfg.conn_add_recurrence)
    path = tmp_path / "neatc.ini"
    path.write_text("[NEAT]\nstagnant_fitness_factor = 0.01\nobliterate_interval = 30\npopulation_stagnation = 20\n"
                    "mutation_exclusive = true\nweight_mutate_neatc = yes\nmate_only_prob = 0.2\n"
                    "conn_add_recurrence = on\nrecur_only_prob = 0.2\n")
    read = NEATConfig.from_ini(path)
    assert (read.stagnant_fitness_factor, read.obliterate_interval, read.population_stagnation) == (0.01, 30, 20)
    assert read.mutation_exclusive and read.weight_mutate_neatc and read.conn_add_recurrence
    assert NEATConfig(**read.to_dict()) == read
    path.write_text("[NEAT]\npopulation_stagnation = 2.5\n")
    with pytest.raises(ConfigError, match="population_stagnation"):
        NEATConfig.from_ini(path)
