"""A user's own plant through the public API: configs made for the task, the spec deciding the
controller, random genomes, and fresh start states per generation (issue 32, items 3-5)."""

import textwrap
from pathlib import Path

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from evolution import (
    NEAT,
    NEATConfig,
    SigmoidController,
    SigmoidSpec,
    SpikingController,
    SpikingSpec,
    TaskFitness,
    check_invariants,
    fresh_starts,
    make_controller,
    random_genomes,
    rollout,
    sigmoid_config,
    spiking_config,
    task_config,
)
from evolution.defaults import TASK_GA, default_spec
from tests.evolution.test_task_seam import PointMass

# --- item 3: the spec decides; a config made for the other controller is an error ------------------

def test_a_spiking_config_for_a_sigmoid_controller_is_an_error_naming_the_field():
    with pytest.raises(ValueError, match=r"compatibility_sigma_coefficient = 100 .*sigmoid controller has no decoder gain"):
        TaskFitness(PointMass(), spiking_config(2, 1), "sigmoid")


def test_one_argument_names_the_controller_so_it_cannot_disagree_with_itself():
    cfg = sigmoid_config(2, 1, pop_size=10)
    assert type(TaskFitness(PointMass(), cfg, "sigmoid").spec) is SigmoidSpec  # a name: its spec's defaults
    assert TaskFitness(PointMass(), cfg, SigmoidSpec(decoder="bang_bang")).spec.decoder == "bang_bang"
    assert isinstance(make_controller(NEAT(cfg).ask(), cfg, PointMass(), "sigmoid"), SigmoidController)
    assert isinstance(make_controller(NEAT(cfg).ask(), cfg, PointMass(), SigmoidSpec()), SigmoidController)
    with pytest.raises(TypeError):  # no second argument (a kind) left to disagree with the spec
        TaskFitness(PointMass(), cfg, "snn", SigmoidSpec())
    with pytest.raises(ValueError, match=r"spec must be one of \['SpikingSpec', 'SigmoidSpec'\] or a name of "
                                         r"\('snn', 'sigmoid'\), got dict"):
        TaskFitness(PointMass(), cfg, spec={"decoder": "bang_bang"})
    with pytest.raises(ValueError, match=r"a controller name must be one of \('snn', 'sigmoid'\), got 'lif'"):
        TaskFitness(PointMass(), cfg, "lif")


def test_a_config_for_another_layout_fails_at_construction_not_at_the_first_evaluation():
    with pytest.raises(ValueError, match=r"2 observations and 1 actions, but the config has num_inputs=4"):
        TaskFitness(PointMass(), sigmoid_config(4, 1), "sigmoid")


def test_the_spec_alone_picks_the_controller():
    task = PointMass()
    cfg = task_config(task, "sigmoid", pop_size=12)
    genomes = NEAT(cfg, seeds=[0, 1]).ask()
    assert isinstance(make_controller(genomes, cfg, task, SigmoidSpec()), SigmoidController)
    spiking = task_config(task, pop_size=12)
    assert isinstance(make_controller(NEAT(spiking).ask(), spiking, task), SpikingController)
    by_spec = TaskFitness(task, cfg, spec=SigmoidSpec(decoder="bang_bang"), episodes=2)
    by_position = TaskFitness(task, cfg, SigmoidSpec(decoder="bang_bang"), episodes=2)
    by_name = TaskFitness(task, cfg, "sigmoid", episodes=2)
    assert isinstance(by_spec.spec, SigmoidSpec)
    assert torch.equal(by_spec(genomes), by_position(genomes))
    # a name stands for the task's default spec, not the spec type's own defaults
    assert by_name.spec == default_spec(task, "sigmoid") != SigmoidSpec()
    assert torch.equal(by_name(genomes), TaskFitness(task, cfg, default_spec(task, "sigmoid"), episodes=2)(genomes))
    assert not torch.equal(by_name(genomes), TaskFitness(task, cfg, SigmoidSpec(), episodes=2)(genomes))


def test_the_default_spiking_spec_reads_the_period_and_whether_observations_are_categories():
    """A measured state: rates over 3 steps of min(period, 10 ms) each (whole 0.5 ms substeps);
    categories (one-hot cells that jump from step to step): rates over the one step, of 30 ms."""
    task = PointMass()  # 20 ms per control step
    spec = default_spec(task, "snn")
    assert (spec.rate_window_steps, spec.network_ms) == (3, 10.0)
    task.control_period_s = 0.0042  # not a whole number of substeps: the whole ones within it
    assert (default_spec(task, "snn").rate_window_steps, default_spec(task, "snn").network_ms) == (3, 4.0)
    task.control_period_s = 0.005
    assert default_spec(task, "snn").network_ms is None  # the period itself
    task.discrete_observations = True
    for period in (0.005, 0.02, 1.0):  # categories have no time between them to model
        task.control_period_s = period
        spec = default_spec(task, "snn")
        assert (spec.rate_window_steps, spec.network_ms) == (1, 30.0)
    assert default_spec(task, "sigmoid") == default_spec(PointMass(), "sigmoid")  # reads the current inputs already


def test_task_config_reads_the_layout_from_the_task():
    task = PointMass()
    sig = task_config(task, "sigmoid", max_hidden=5)
    assert (sig.num_inputs, sig.num_outputs, sig.num_bias, sig.max_hidden) == (2, 1, 1, 5)
    assert sig.compatibility_sigma_coefficient == 0.0 and sig.sigma_mutate_rate == 0.0
    assert task_config(task, SigmoidSpec(), max_hidden=5) == sig
    assert task_config(task, SpikingSpec()) == spiking_config(2, 1, **TASK_GA) == task_config(task)
    assert (sig.initial_hidden, task_config(task).initial_hidden) == (5, 16)  # the start's layer fits max_hidden
    assert task_config(task, max_hidden=20, initial_hidden=3).initial_hidden == 3
    TaskFitness(task, sig, "sigmoid")  # accepted as it is


# --- item 4: random genomes -------------------------------------------------------------------------

@settings(max_examples=25, deadline=None)
@given(inputs=st.integers(1, 4), bias=st.integers(0, 2), outputs=st.integers(1, 3), max_hidden=st.integers(0, 6),
       data=st.data(), feed_forward=st.booleans(), density=st.floats(0.0, 1.0), seed=st.integers(0, 2**31))
def test_random_genomes_hold_every_invariant(inputs, bias, outputs, max_hidden, data, feed_forward, density, seed):
    cfg = NEATConfig(num_inputs=inputs, num_bias=bias, num_outputs=outputs, max_hidden=max_hidden, pop_size=5,
                     feed_forward=feed_forward)
    hidden = data.draw(st.integers(0, max_hidden))
    genomes = random_genomes(cfg, runs=2, hidden=hidden, density=density, seed=seed)
    check_invariants(genomes, cfg)
    assert bool((genomes.num_hidden(cfg) == hidden).all())
    assert bool((genomes.enabled == genomes.conn).all())
    again = random_genomes(cfg, runs=2, hidden=hidden, density=density, seed=seed)
    assert all(torch.equal(a, b) for a, b in zip(genomes.tensors().values(), again.tensors().values(), strict=True))


def test_random_genomes_density_spans_none_to_every_possible_gene():
    cfg = NEATConfig(num_inputs=2, num_bias=1, num_outputs=1, max_hidden=3, pop_size=4)
    assert int(random_genomes(cfg, hidden=3, density=0.0).conn.sum()) == 0
    full = random_genomes(cfg, hidden=3, density=1.0)
    # 7 nodes; genes into the output and 3 hidden nodes (4 targets) from all 7 sources, per genome
    assert full.num_genes().tolist() == [[28] * 4]
    ff = random_genomes(NEATConfig(**{**cfg.to_dict(), "feed_forward": True}), hidden=3, density=1.0)
    check_invariants(ff, NEATConfig(**{**cfg.to_dict(), "feed_forward": True}))
    assert int(ff.num_genes()[0, 0]) == 3 * 4 + 3 + 2 + 1  # into the output from 6; hidden k from 3 + k earlier


@pytest.mark.parametrize("field,value", [("runs", 0), ("hidden", 4), ("density", 1.5), ("hidden", True)])
def test_random_genomes_reject_bad_arguments_by_name(field, value):
    cfg = NEATConfig(num_inputs=2, num_outputs=1, max_hidden=3, pop_size=4)
    with pytest.raises(ValueError, match=f"random_genomes: {field} = "):
        random_genomes(cfg, **{field: value})


# --- item 5: fresh start states per generation ------------------------------------------------------

def _starts_of(fitness_fn, genomes):
    """The first observation of each row, as the rollout saw it."""
    controller = make_controller(genomes, fitness_fn.config, fitness_fn.task, fitness_fn.spec)
    starts = fresh_starts(fitness_fn.task, genomes, fitness_fn.episodes, fitness_fn.seed)
    return rollout(fitness_fn.task, controller, episodes=fitness_fn.episodes, starts=starts, max_steps=1,
                   record=True).trace["observation"][0]


def test_fresh_starts_change_each_generation_and_belong_to_the_run():
    task = PointMass()
    cfg = task_config(task, "sigmoid", pop_size=6)
    fitness = TaskFitness(task, cfg, "sigmoid", episodes=3, seed=5, fresh_starts=True)
    neat = NEAT(cfg, seeds=[0, 1, 2])
    first = neat.ask()
    neat.tell(fitness(first))
    second = neat.ask()
    s1, s2 = _starts_of(fitness, first), _starts_of(fitness, second)
    rows = s1.view(3, 6, 3, 2)
    # every genome of a run shares its run's starts; runs and generations differ
    assert torch.equal(rows, rows[:, :1].expand_as(rows))
    assert not torch.equal(rows[0, 0], rows[1, 0]) and not torch.equal(s1, s2)
    # a run's starts (and so its fitness) do not depend on the other runs beside it
    alone = fitness(second.select_runs([1]))
    assert torch.equal(alone[0], fitness(second)[1])
    assert torch.equal(_starts_of(fitness, second.select_runs([2])), s2.view(3, 18, 2)[2])
    # the seed matters
    other = TaskFitness(task, cfg, "sigmoid", episodes=3, seed=6, fresh_starts=True)
    assert not torch.equal(_starts_of(other, second), s2)


def test_fixed_starts_stay_the_default_and_fresh_starts_exclude_them():
    task = PointMass()
    cfg = task_config(task, "sigmoid", pop_size=6)
    fixed = TaskFitness(task, cfg, "sigmoid", episodes=3, seed=5)
    neat = NEAT(cfg, seeds=[0])
    g1 = neat.ask()
    neat.tell(fixed(g1))
    g2 = neat.ask()
    controller = make_controller(g2, cfg, task)
    first = rollout(task, controller, episodes=3, seed=5, max_steps=1, record=True).trace["observation"][0]
    assert torch.equal(first.view(6, 3, 2), first.view(6, 3, 2)[:1].expand(6, 3, 2))
    with pytest.raises(ValueError, match="fixed starts= or fresh_starts=True, not both"):
        TaskFitness(task, cfg, "sigmoid", starts=torch.zeros(3, 2), fresh_starts=True)


def test_a_run_with_fresh_starts_resumes_to_the_same_bits():
    task = PointMass()
    cfg = task_config(task, pop_size=12)
    fitness = TaskFitness(task, cfg, "snn", episodes=2, seed=1, fresh_starts=True, max_steps=30)
    straight = NEAT(cfg, seeds=[3, 4])
    straight.run(fitness, generations=4)
    first = NEAT(cfg, seeds=[3, 4])
    first.run(fitness, generations=2)
    resumed = NEAT.from_state_dict(first.state_dict())
    resumed.run(fitness, generations=2)
    assert torch.equal(resumed.best_fitness, straight.best_fitness)
    assert all(torch.equal(a, b) for a, b in zip(resumed.ask().tensors().values(), straight.ask().tensors().values(),
                                                 strict=True))


def test_per_row_starts_are_checked_like_shared_ones():
    task = PointMass()
    cfg = task_config(task, "sigmoid", pop_size=4)
    genomes = NEAT(cfg, seeds=[0]).ask()
    controller = make_controller(genomes, cfg, task)
    starts = fresh_starts(task, genomes, 2, 0)
    starts[5, 0] = float("nan")
    with pytest.raises(Exception, match=r"NaN or inf at 1 of 8 start\(s\), first: \(genome 2, episode 1\)"):
        rollout(task, controller, episodes=2, starts=starts)
    with pytest.raises(Exception, match=r"start states have 5 rows, expected 2 \(one per episode"):
        rollout(task, controller, episodes=2, starts=torch.zeros(5, 2))


# --- the docs' example, as a user copies it -----------------------------------------------------------

def _doc_blocks(language: str) -> list[str]:
    text = (Path(__file__).resolve().parents[2] / "docs" / "writing-a-task.md").read_text()
    return [textwrap.dedent(b.split("```")[0]) for b in text.split("```" + language + "\n")[1:]]


def test_the_docs_pendulum_example_evolves_and_its_random_genomes_run():
    """docs/writing-a-task.md's first example (fewer runs and generations) and its random genomes."""
    blocks = _doc_blocks("python")
    example = next(b for b in blocks if "class Pendulum(Task)" in b)
    small = example.replace("seeds=range(8)", "seeds=range(2)").replace("generations=50", "generations=2")
    assert small.count("range(2)") == 1 and "generations=2" in small
    namespace: dict = {}
    exec(small, namespace)
    assert isinstance(namespace["fitness"].spec, SpikingSpec) and namespace["fitness"].fresh_starts
    assert namespace["result"].best_fitness.shape == (2,)
    assert namespace["trace"]["action"].shape[1:] == (2, 1)
    exec(next(b for b in blocks if "random_genomes(" in b), namespace)
    assert namespace["steps"].shape == (64, 2) and int(namespace["steps"].min()) >= 1


def _python_block(path: Path, marker: str) -> str:
    text = path.read_text()
    return next(b.split("```")[0] for b in text.split("```python\n")[1:] if marker in b)


def test_your_own_plants_python_runs_the_defaults_as_written():
    """docs/your-own-plant.md's Python (2 generations instead of 100): the library's defaults for
    the task, nothing set but the plant, the controller and a budget."""
    root = Path(__file__).resolve().parents[2]
    block = _python_block(root / "docs" / "your-own-plant.md", 'GymTask("Pendulum-v1")')
    small = block.replace("generations=100", "generations=2")
    assert small.count("generations=2") == 1
    namespace: dict = {}
    exec(small, namespace)
    task, config, fitness = namespace["task"], namespace["config"], namespace["fitness"]
    assert fitness.spec == default_spec(task, "sigmoid") and fitness.spec.updates_per_step == 3
    assert all(getattr(config, k) == v for k, v in TASK_GA.items())
    assert fitness.fresh_starts and fitness.episodes == 16
    assert namespace["result"].best_fitness.shape == (5,)


def test_the_readmes_quick_start_on_your_own_plant_runs():
    root = Path(__file__).resolve().parents[2]
    block = _python_block(root / "README.md", 'GymTask("Pendulum-v1")')
    small = block.replace("generations=100", "generations=2")
    assert small != block
    namespace: dict = {}
    exec(small, namespace)
    assert namespace["result"].best_fitness.shape == (4,)
    task, fitness = namespace["task"], namespace["fitness"]
    assert namespace["config"].num_inputs == 3 and fitness.spec == default_spec(task, "snn")
    assert fitness.spec.input_coding == "signed" and fitness.fresh_starts


def test_the_docs_own_controller_example_runs_through_the_seam():
    """docs/writing-a-task.md's own controller, on its pendulum, registered and scored by TaskFitness."""
    from evolution.phenotype import CONTROLLER_NAMES, CONTROLLERS

    blocks = _doc_blocks("python")
    namespace: dict = {}
    pendulum = next(b for b in blocks if "class Pendulum(Task)" in b)
    exec(pendulum.split("config = task_config")[0], namespace)  # the task only
    try:
        exec(next(b for b in blocks if "class ProportionalController" in b), namespace)
        scores = namespace["scores"]
        assert scores.shape == (2, 16) and bool(torch.isfinite(scores).all())
        assert len(set(scores.flatten().tolist())) > 1  # the weights matter
    finally:
        CONTROLLERS.pop(namespace.get("ProportionalSpec"), None)
        CONTROLLER_NAMES.pop("proportional", None)
