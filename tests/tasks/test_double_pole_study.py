"""The double-pole study (snn-neat reproduce dpv|dpnv): NEAT 2002's setups, its test of a
solution, evaluations counted as it counts them, and the report."""

import json
from dataclasses import replace

import pytest
import torch

from evolution import NEAT, TaskFitness
from evolution.checkpoint import load_checkpoint_dict
from tasks.studies.distributed import run_controller_sharded
from tasks.studies.double_pole import (
    CODINGS,
    DPNV_EPISODE_STEPS,
    FITNESSES,
    LONG_BALANCE_STEPS,
    OBSERVATION_BOUNDS,
    POPULATION,
    PUBLISHED,
    PUSH_PULL_INPUT_NA,
    damping_fitness_starts,
    study_config,
    study_fitness,
    study_solved,
    study_spec,
    study_task,
)
from tasks.studies.double_pole_report import format_study_markdown, study_rows, write_study_report
from tasks.studies.registry import STUDIES
from tasks.studies.reproduce import ReproduceError, run_controller


def test_the_variants_are_neat_2002s_setups():
    dpv, dpnv = study_task("dpv"), study_task("dpnv")
    assert dpv.velocities and not dpnv.velocities and dpnv.damping and not dpv.damping
    assert (dpv.max_steps, dpnv.max_steps) == (LONG_BALANCE_STEPS, 1000)
    assert dpv.observation_high == OBSERVATION_BOUNDS["dpv"] and dpnv.observation_high == OBSERVATION_BOUNDS["dpnv"]
    for variant in ("dpv", "dpnv"):
        for kind in ("snn", "sigmoid"):
            cfg = study_config(variant, kind)
            assert cfg.pop_size == POPULATION[variant] and cfg.num_inputs == study_task(variant).observation_size
            assert cfg.num_bias == (1 if kind == "sigmoid" else 0)
            assert cfg.survival_threshold == 0.1 and cfg.weight_mutate_per_gene  # the tuned GA by default
    assert study_config("dpv", "snn").fitness_threshold == LONG_BALANCE_STEPS  # a full balance solves DPV
    assert study_solved("dpv", "snn", study_config("dpv", "snn")) is None
    assert [p["evaluations"] for p in PUBLISHED["dpnv"] if p["method"] == "NEAT"] == [33_184]
    with pytest.raises(ValueError, match="variant must be one of"):
        study_task("dpx")
    with pytest.raises(ValueError, match="controller must be one of"):
        study_config("dpv", "lstm")


def test_dpnv_solves_only_by_the_champion_test():
    cfg = study_config("dpnv", "sigmoid", pop_size=10)
    neat = NEAT(cfg, seeds=[1, 2])
    genomes = neat.ask()
    fitness = study_fitness("dpnv", "sigmoid", cfg)(genomes)
    assert fitness.shape == (2, 10) and float(fitness.max()) < 0.1  # damping fitness: t / 1000 / 10 early on
    solved = study_solved("dpnv", "sigmoid", cfg)(genomes, fitness)
    assert solved.shape == (2, 10) and solved.dtype == torch.bool and not bool(solved.any())


def test_reproduce_dpv_writes_the_study_report(tmp_path):
    out = tmp_path / "dpv"
    results = {c: run_controller("dpv", c, [0, 1], 2, out, progress=False, ga="neat-c++") for c in ("snn", "sigmoid")}
    r = results["sigmoid"]
    assert r.config.pop_size == 150 and r.history.shape == (2, 2)
    r.solved_generation = [2, -1]  # pretend run 0 solved at generation 2, to check the counting
    summary = study_rows(results, "dpv", generalization=False)
    row = summary["rows"]["sigmoid"]
    assert summary["runs"]["sigmoid"]["evaluations"] == [300, 450]  # generations x 150, failure as budget + 1
    assert (row["solved"], row["failures"], row["evaluations_mean_solved"]) == (1, 1, 300)
    paths = write_study_report(results, "dpv", out, command="test", generalization=True)
    names = {p.name for p in paths}
    assert {"dpv.md", "summary.json", "runs.csv", "best_fitness.png", "evaluations_to_solve.png",
            "generalization.png", "topology_snn.png", "trajectory_sigmoid.png", "sigmoid_seed1.json"} <= names
    md = (out / "dpv.md").read_text()
    assert "| NEAT | NEAT02 Table 1 | 150 | 3,600 |" in md and "| NEAT original (sigmoid) | this code | 150 | 300 |" in md
    saved = json.loads((out / "summary.json").read_text())
    assert len(saved["runs"]["snn"]["generalization"]) == 2
    assert all(0 <= g <= 625 for g in saved["runs"]["snn"]["generalization_static_map"])
    steps = saved["runs"]["sigmoid"]["standard_start"]  # the champions' balance, up to 1000 steps
    assert steps == [min(int(f), 1000) for f in saved["runs"]["sigmoid"]["best_fitness"]]
    assert "Hold the standard start 1000 steps" in md


def test_the_signed_coding_is_neat_121s_and_reaches_the_networks():
    for variant, scales in (("dpv", (4.8, 2.0, 0.52, 2.0, 0.52, 2.0)), ("dpnv", (4.8, 0.52, 0.52))):
        task = study_task(variant, "signed")
        assert task.observation_high == scales and task.observation_low == tuple(-s for s in scales)
        for kind in ("snn", "sigmoid"):
            spec = study_spec(variant, kind, "signed")
            assert (spec.input_coding, spec.clip_inputs) == ("signed", False)
            assert study_config(variant, kind, coding="signed").num_inputs == len(scales)
    cfg = study_config("dpv", "sigmoid", pop_size=20)
    genomes = NEAT(cfg, seeds=[3]).ask()
    study = study_fitness("dpv", "sigmoid", cfg)(genomes)
    signed = study_fitness("dpv", "sigmoid", cfg, "signed")(genomes)
    assert not torch.equal(study, signed)
    with pytest.raises(ValueError, match=r"coding must be one of \('study', 'signed', 'push-pull'\)"):
        study_task("dpv", "push_pull")


def test_the_push_pull_coding_feeds_two_nodes_per_variable_and_snn_its_own_gain():
    assert STUDIES["dpv"].codings == STUDIES["dpnv"].codings == CODINGS  # the CLI offers what the study has
    for variant, scales in (("dpv", (4.8, 2.0, 0.52, 2.0, 0.52, 2.0)), ("dpnv", (4.8, 0.52, 0.52))):
        assert study_task(variant, "push-pull").observation_high == scales
        for kind in ("snn", "sigmoid"):
            spec = study_spec(variant, kind, "push-pull")
            assert (spec.input_coding, spec.clip_inputs) == ("push_pull", False)
            assert study_config(variant, kind, coding="push-pull").num_inputs == 2 * len(scales)
    snn, signed = study_spec("dpnv", "snn", "push-pull"), study_spec("dpnv", "snn", "signed")
    assert snn.i_input_max == PUSH_PULL_INPUT_NA != signed.i_input_max
    assert replace(snn, input_coding="signed", i_input_max=signed.i_input_max) == signed  # nothing else differs
    # the gain reaches the spiking networks: the same genomes score otherwise at the signed coding's gain
    cfg = study_config("dpnv", "snn", coding="push-pull", pop_size=16)
    genomes = NEAT(cfg, seeds=[4]).ask()
    pushed = study_fitness("dpnv", "snn", cfg, "push-pull")(genomes)
    low_gain = TaskFitness(study_task("dpnv", "push-pull"), cfg, replace(snn, i_input_max=signed.i_input_max))(genomes)
    assert pushed.shape == (1, 16) and not torch.equal(pushed, low_gain)


def test_reproduce_dpnv_with_the_push_pull_coding_records_it_in_the_report(tmp_path):
    out = tmp_path / "pp"
    r = run_controller("dpnv", "snn", [0], 2, out, progress=False, coding="push-pull",
                       ga="neat-1.2.1-dpnv-per-gene", fitness_starts=2)
    assert r.extra["coding"] == "push-pull" and r.config.num_inputs == 6
    with pytest.raises(ReproduceError, match=r"written with coding='push-pull', this call asks for coding='signed'"):
        run_controller("dpnv", "snn", [0], 2, out, progress=False, resume=True, coding="signed",
                       ga="neat-1.2.1-dpnv-per-gene", fitness_starts=2)
    write_study_report({"snn": r}, "dpnv", out, command="test", generalization=False)
    md = (out / "dpnv.md").read_text()
    assert "Input coding: push-pull" in md and "300 nA per unit" in md and "4.8, 0.52, 0.52" in md
    assert "Input coding: signed" not in md
    with pytest.raises(ReproduceError, match=r"coding must be one of \('study', 'signed'\) for table2"):
        run_controller("table2", "snn", [0], 1, tmp_path / "t2", progress=False, coding="push-pull")


def test_reproduce_with_the_signed_coding_records_it_and_resumes_only_with_it(tmp_path):
    out = tmp_path / "dpv"
    r = run_controller("dpv", "sigmoid", [0, 1], 2, out, progress=False, coding="signed")
    assert r.extra["coding"] == "signed" and r.config == study_config("dpv", "sigmoid", coding="signed")
    again = run_controller("dpv", "sigmoid", [0, 1], 3, tmp_path / "again", progress=False, coding="signed")
    assert again.history[:2].equal(r.history)  # the same runs, one generation further
    with pytest.raises(ReproduceError, match=r"written with coding='signed', this call asks for coding='study'"):
        run_controller("dpv", "sigmoid", [0, 1], 2, out, progress=False, resume=True, setup="neat-2002")
    write_study_report({"sigmoid": r}, "dpv", out, command="test", generalization=False)
    md = (out / "dpv.md").read_text()
    assert "Input coding: signed, as NEAT C++ 1.2.1 feeds its networks" in md and "4.8, 2, 0.52, 2, 0.52, 2" in md
    assert json.loads((out / "summary.json").read_text())["rows"]["sigmoid"]["coding"] == "signed"
    with pytest.raises(ReproduceError, match=r"coding must be one of \('study', 'signed'\)"):
        run_controller("table2", "sigmoid", [0], 1, tmp_path / "t2", progress=False, coding="unit")


def test_evaluations_are_also_counted_as_neat_121_counts_them(tmp_path):
    """population x (generation - 1) + the first solving genome's 1-based position in its generation."""
    from tasks.studies.double_pole_report import neat121_evaluations

    cfg = study_config("dpv", "sigmoid", pop_size=10, fitness_threshold=50.0)
    neat = NEAT(cfg, seeds=[0, 1, 2])
    fitness = torch.zeros(3, 10, dtype=torch.float64)
    fitness[0, 7], fitness[0, 9] = 60.0, 80.0  # run 0: genomes 7 and 9 solve in generation 1
    neat.tell(fitness)
    fitness = torch.zeros(3, 10, dtype=torch.float64)
    fitness[1, 3] = 55.0  # run 1: genome 3 in generation 2; run 2 never
    neat.tell(fitness)
    assert neat.solved_generation.tolist() == [1, 2, -1] and neat.solved_position.tolist() == [7, 3, -1]
    assert neat.result().solved_position.tolist() == [7, 3, -1]
    again = NEAT.from_state_dict(neat.state_dict())  # kept in checkpoints
    assert again.solved_position.tolist() == [7, 3, -1]
    old = neat.state_dict()
    del old["solved_position"]  # a checkpoint from before: positions unknown
    assert NEAT.from_state_dict(old).solved_position.tolist() == [-1, -1, -1]
    r = run_controller("dpv", "sigmoid", [0, 1], 1, tmp_path, progress=False)
    r.solved_generation, r.extra["solved_position"] = [1, 3], [7, 3]
    assert neat121_evaluations(r) == [8, 304]
    r.extra["solved_position"] = [-1, 3]
    assert neat121_evaluations(r) == [None, 304]
    summary = study_rows({"sigmoid": r}, "dpv", generalization=False)
    assert summary["rows"]["sigmoid"]["evaluations_neat121_mean_solved"] == 304
    # beside NEAT C++ 1.2.1's own runs (tasks/studies/neat121_runs.json): one solved run of 304, one failure
    against = summary["against_neat121"]["sigmoid"]
    assert against["median"] == 304 and against["failures"] == 1 and against["neat121_runs"] >= 100
    assert 0.0 < against["mann_whitney_p"] < 0.5 and 0.0 < against["fisher_p"] <= 1.0
    summary.update(seeds=[0, 1])
    md = format_study_markdown(summary, "cmd")
    assert "Against NEAT C++ 1.2.1's own runs" in md and f"| {against['mann_whitney_p']:.3g} | 1/2 |" in md


def test_neat_121s_test_takes_the_best_unchecked_species_and_unchecks_on_a_record():
    """One champion per run and generation (pole2_epoch): the best unchecked species' first, the best
    species' when all are checked; a species is unchecked by a record of its best fitness and stays so
    until tested, whatever its fitness does meanwhile."""
    from tasks.studies.double_pole import SpeciesChampionTest

    cfg = study_config("dpnv", "sigmoid", pop_size=6)
    neat = NEAT(cfg, seeds=[0, 1])
    S = neat.species_state.ident.shape[1]
    neat.species = torch.tensor([[0, 0, 1, 1, 2, 2], [0, 0, 0, 0, 0, 0]])
    neat.species_state.ident[:] = torch.arange(S) + 10
    tested = []

    def test(champions):  # records the champions' first weights; only run 1's passes
        tested.append(champions.weight[:, 0].clone())
        return torch.tensor([False, True])

    check = SpeciesChampionTest(neat, test)
    genomes = neat.ask()
    genomes.weight[:, :, 0, 3] = torch.arange(6, dtype=genomes.weight.dtype)  # a genome's mark: its index
    f = torch.tensor([[0.1, 0.5, 0.7, 0.2, 0.3, 0.3], [0.2, 0.9, 0.1, 0.9, 0.0, 0.0]], dtype=torch.float64)
    out = check(genomes, f)
    assert tested[-1][:, 0, 3].tolist() == [2.0, 1.0]  # species 1's champion; run 1: the first of two best
    assert out.tolist() == [[False] * 6, [False, True, False, False, False, False]]
    marks = []
    for fitness in (f, f):  # nothing improves: species 0's champion (0.5) next, then species 2's first best
        check(genomes, fitness)
        marks.append(float(tested[-1][0, 0, 3]))
    assert marks == [1.0, 4.0]
    check(genomes, f)  # every species checked: the best species' champion again
    assert tested[-1][0, 0, 3] == 2.0
    f2 = f.clone()
    f2[0, 3], f2[0, 5] = 0.8, 0.35  # species 1 and 2 set records: both unchecked, the better tested
    check(genomes, f2)
    assert tested[-1][0, 0, 3] == 3.0
    check(genomes, f)  # species 2 fell back below its record but stays unchecked until tested
    assert tested[-1][0, 0, 3] == 4.0
    check(genomes, f)
    assert tested[-1][0, 0, 3] == 2.0  # all checked again
    assert len(tested) == 7  # one test every generation
    state = check.state_dict()
    again = SpeciesChampionTest(neat, test)
    again.load_state_dict(state)
    assert again.checked == check.checked and again.record == check.record
    assert again.record[0] == {10: 0.5, 11: 0.8, 12: 0.35}
    with pytest.raises(ValueError, match="must list 2 runs"):
        again.load_state_dict({"checked": [], "record": []})
    with pytest.raises(ValueError, match="before 2026-12-06"):
        again.load_state_dict({"tested": [{}, {}]})


def test_reproduce_dpnv_with_neat_121s_test_resumes_to_the_same_bits(tmp_path):
    straight = run_controller("dpnv", "sigmoid", [0, 1], 3, tmp_path / "straight", progress=False,
                              champion_test="species")
    run_controller("dpnv", "sigmoid", [0, 1], 3, tmp_path / "split", progress=False, champion_test="species",
                   stop_after=1)
    saved = load_checkpoint_dict(tmp_path / "split" / "sigmoid.ckpt")
    assert len(saved["solved_state"]["checked"]) == 2 and all(saved["solved_state"]["checked"])  # a species each
    resumed = run_controller("dpnv", "sigmoid", [0, 1], 3, tmp_path / "split", progress=False,
                             champion_test="species", resume=True)
    assert torch.equal(resumed.history, straight.history) and resumed.solved_generation == straight.solved_generation
    assert resumed.extra["champion_test"] == "species"
    # the tests of a solution are part of the cost, kept across the interruption
    assert 0 < saved["solve_test_cpu_s"] <= saved["cpu_s"]
    assert saved["solve_test_cpu_s"] < resumed.extra["solve_test_cpu_s"] <= resumed.extra["cpu_s"]
    rows = study_rows({"sigmoid": resumed}, "dpnv", generalization=False)["rows"]["sigmoid"]
    assert rows["solve_test_cpu_s"] == resumed.extra["solve_test_cpu_s"] and rows["report_tests_cpu_s"] >= 0
    assert "What the runs cost (CPU seconds" in format_study_markdown({**study_rows({"sigmoid": resumed}, "dpnv"),
                                                                       "seeds": [0, 1]}, "test")
    with pytest.raises(ReproduceError, match="champion_test='species', this call asks for champion_test='champion'"):
        run_controller("dpnv", "sigmoid", [0, 1], 3, tmp_path / "split", progress=False, resume=True,
                       champion_test="champion")
    # the species test is DPNV's default: a call that names none resumes it
    default = run_controller("dpnv", "sigmoid", [0, 1], 3, tmp_path / "split", progress=False, resume=True)
    assert default.extra["champion_test"] == "species" and default.solved_generation == straight.solved_generation
    with pytest.raises(ReproduceError, match="'species' only for dpnv"):
        run_controller("dpv", "sigmoid", [0], 1, tmp_path / "dpv", progress=False, champion_test="species")


def test_the_fitness_starts_are_the_standard_one_then_fixed_random_ones_in_gruaus_ranges():
    from tasks.studies.generalization import GRUAU_RANGES

    task = study_task("dpnv", "signed")
    starts = damping_fitness_starts(task, 50)
    assert starts.shape == (50, task.reset(1).shape[1]) and starts.dtype == torch.float64
    assert torch.equal(starts[0], task.reset(1)[0])  # the standard start first
    assert torch.equal(damping_fitness_starts(task, 1), task.reset(1))
    assert torch.equal(damping_fitness_starts(task, 50), starts)  # fixed: the same starts every call
    assert torch.equal(damping_fitness_starts(task, 8)[1:], starts[1:8])  # K grows by adding starts
    ranges = torch.tensor(GRUAU_RANGES, dtype=torch.float64)
    assert bool((starts[1:, :4].abs() <= ranges).all()) and bool((starts[1:, 4:] == 0).all())  # short pole at rest
    assert bool((starts[1:, :4].abs() > ranges / 2).any(0).all())  # spread over the ranges, not clustered
    assert not torch.equal(damping_fitness_starts(task, 50, seed=1), starts)
    for bad in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="fitness_starts must be an int >= 1"):
            damping_fitness_starts(task, bad)


def test_a_fitness_over_k_starts_is_the_mean_of_each_starts_damping_fitness():
    from evolution import TaskFitness

    for kind in ("sigmoid", "snn"):
        cfg = study_config("dpnv", kind, coding="signed", pop_size=12)
        genomes = NEAT(cfg, seeds=[3]).ask()
        task, spec = study_task("dpnv", "signed"), study_spec("dpnv", kind, "signed")
        starts = damping_fitness_starts(task, 3)
        each = torch.stack([TaskFitness(task, cfg, spec, starts=starts[k:k + 1])(genomes) for k in range(3)])
        together = study_fitness("dpnv", kind, cfg, "signed", fitness_starts=3)(genomes)
        assert torch.allclose(together.double(), each.double().mean(0), rtol=1e-6, atol=0), kind
        assert torch.equal(study_fitness("dpnv", kind, cfg, "signed", fitness_starts=1)(genomes), each[0])
        assert not torch.allclose(each[1], each[0])  # the other starts change what a genome scores
    with pytest.raises(ValueError, match="only dpnv's damping fitness runs over several starts"):
        study_fitness("dpv", "sigmoid", study_config("dpv", "sigmoid"), fitness_starts=2)


def test_reproduce_dpnv_with_fitness_starts_records_them_and_resumes_only_with_them(tmp_path):
    out = tmp_path / "k2"
    kw = dict(progress=False, setup="neat-2002", ga="neat-1.2.1-dpnv-per-gene", coding="signed")
    r = run_controller("dpnv", "sigmoid", [0, 1], 2, out, fitness_starts=2, **kw)
    one = run_controller("dpnv", "sigmoid", [0, 1], 2, tmp_path / "k1", **kw)
    assert r.extra["fitness_starts"] == 2 and one.extra["fitness_starts"] == 1
    assert not torch.equal(r.history, one.history)  # the option reaches the fitness
    with pytest.raises(ReproduceError, match=r"fitness_starts=2, this call asks for fitness_starts=1"):
        run_controller("dpnv", "sigmoid", [0, 1], 2, out, resume=True, **kw)
    assert run_controller("dpnv", "sigmoid", [0, 1], 2, out, resume=True, fitness_starts=2, **kw).history.equal(r.history)
    # a checkpoint written before the option existed holds no fitness_starts: it ran with one start
    from evolution.checkpoint import atomic_torch_save

    old = load_checkpoint_dict(tmp_path / "k1" / "sigmoid.ckpt")
    del old["identity"]["fitness_starts"]
    atomic_torch_save(old, tmp_path / "k1" / "sigmoid.ckpt")
    assert run_controller("dpnv", "sigmoid", [0, 1], 2, tmp_path / "k1", resume=True, **kw).history.equal(one.history)
    with pytest.raises(ReproduceError, match=r"fitness_starts=1, this call asks for fitness_starts=2"):
        run_controller("dpnv", "sigmoid", [0, 1], 2, tmp_path / "k1", resume=True, fitness_starts=2, **kw)
    write_study_report({"sigmoid": r}, "dpnv", out, command="test", generalization=False)
    md = (out / "dpnv.md").read_text()
    assert "Fitness: the mean damping fitness over 2 episodes" in md and "`--fitness-starts 2`" in md
    assert json.loads((out / "summary.json").read_text())["rows"]["sigmoid"]["fitness_starts"] == 2
    assert "fitness_starts" not in study_rows({"sigmoid": one}, "dpnv", generalization=False)["rows"]["sigmoid"]
    for bad in (0, 1.5):
        with pytest.raises(ReproduceError, match="fitness_starts must be an int >= 1"):
            run_controller("dpnv", "sigmoid", [0], 1, tmp_path / "bad", fitness_starts=bad, **kw)
    with pytest.raises(ReproduceError, match="fitness_starts must be 1 for table2"):
        run_controller("table2", "sigmoid", [0], 1, tmp_path / "t2", progress=False, fitness_starts=3)


def test_min_general_is_the_generalisation_starts_a_dpnv_solution_must_hold(monkeypatch):
    """Both tests of a generation accept a champion that balances 100,000 steps only when it holds
    ``min_general`` of the 625 starts: the count it holds passes, one more fails."""
    import tasks.studies.double_pole as dp

    held = 250  # a fake plant: every champion balances the long run and the first `held` starts

    def balanced(champions, config, spec=None, *, velocities=False, max_steps=None, starts=None, task=None):
        R = champions.num_runs
        if starts is None:
            return torch.full((R, 1, 1), max_steps)
        return (torch.arange(starts.shape[0]) < held).long().mul(1000).expand(R, 1, -1)

    monkeypatch.setattr(dp, "balanced_steps", balanced)
    cfg = study_config("dpnv", "sigmoid", pop_size=6)
    neat = NEAT(cfg, seeds=[0, 1])
    genomes = neat.ask()
    fitness = torch.rand(2, 6, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    for test in ("champion", "species"):
        def solves(n, test=test):
            kw = {} if n is None else {"min_general": n}
            return study_solved("dpnv", "sigmoid", cfg, champion_test=test, neat=neat, **kw)(genomes, fitness)

        assert solves(None).sum(-1).tolist() == [1, 1]  # NEAT 2002's 200
        assert solves(held).sum(-1).tolist() == [1, 1] and not bool(solves(held + 1).any()), test
    assert dp.champions_test(genomes.gather(torch.zeros(2, 1, dtype=torch.long)), cfg)[1].tolist() == [held, held]
    for bad in (-1, 626, 300.0, True):
        with pytest.raises(ValueError, match=r"min_general must be an int of generalisation starts in 0\.\.625"):
            study_solved("dpnv", "sigmoid", cfg, min_general=bad)
    with pytest.raises(ValueError, match="only dpnv's test of a solution counts generalisation starts"):
        study_solved("dpv", "sigmoid", study_config("dpv", "sigmoid"), min_general=300)


def test_only_the_champions_that_hold_the_long_balance_take_the_625_starts(monkeypatch):
    """The generalisation starts run for the champions that balanced the 100,000 steps and no
    other: a champion that fell is reported as not run (-1), whatever it would have held."""
    import tasks.studies.double_pole as dp

    long_steps = torch.tensor([100_000, 50, 100_000, 7])  # runs 0 and 2 hold the long balance
    general_rows = []

    def balanced(champions, config, spec=None, *, velocities=False, max_steps=None, starts=None, task=None):
        tag = champions.weight.flatten(1)[:, 0]  # each run's own mark, to see which runs arrive
        if starts is None:
            return long_steps[tag.long()].view(-1, 1, 1)
        general_rows.append(tag.long().tolist())
        return (torch.arange(starts.shape[0]) < 100 * (tag.long() + 1).view(-1, 1)).long().mul(1000).unsqueeze(1)

    monkeypatch.setattr(dp, "balanced_steps", balanced)
    cfg = study_config("dpnv", "sigmoid", pop_size=6)
    champions = NEAT(cfg, seeds=[0, 1, 2, 3]).ask().gather(torch.zeros(4, 1, dtype=torch.long))
    champions.weight.view(4, -1)[:, 0] = torch.arange(4, dtype=champions.weight.dtype)
    solved, held = dp.champions_test(champions, cfg, min_general=250)
    assert general_rows == [[0, 2]]
    assert held.tolist() == [100, -1, 300, -1] and solved.tolist() == [False, False, True, False]


def test_reproduce_dpnv_with_min_general_records_it_and_resumes_only_with_it(tmp_path):
    kw = dict(progress=False, setup="neat-2002", ga="neat-1.2.1-dpnv-per-gene", coding="signed")
    out = tmp_path / "m300"
    r = run_controller("dpnv", "sigmoid", [0], 1, out, min_general=300, **kw)
    assert r.extra["min_general"] == 300
    with pytest.raises(ReproduceError, match=r"min_general=300, this call asks for min_general=None"):
        run_controller("dpnv", "sigmoid", [0], 1, out, resume=True, **kw)
    # NEAT 2002's 200, named or not, is one identity: a run resumes whichever way it is spelled
    one = run_controller("dpnv", "sigmoid", [0], 1, tmp_path / "m200", min_general=200, **kw)
    assert one.extra["min_general"] is None
    run_controller("dpnv", "sigmoid", [0], 2, tmp_path / "m200", resume=True, **kw)
    write_study_report({"sigmoid": r}, "dpnv", out, command="test", generalization=False)
    md = (out / "dpnv.md").read_text()
    assert "and 300 (not NEAT 2002's 200) of the 625 generalisation starts" in md and "`--min-general 300`" in md
    assert "a stricter test" in md
    looser = study_rows({"sigmoid": r}, "dpnv", generalization=False)
    looser["rows"]["sigmoid"]["min_general"] = 150
    looser.update(seeds=[0])
    assert "a looser test" in format_study_markdown(looser, "cmd")
    assert json.loads((out / "summary.json").read_text())["rows"]["sigmoid"]["min_general"] == 300
    assert "min_general" not in study_rows({"sigmoid": one}, "dpnv", generalization=False)["rows"]["sigmoid"]
    with pytest.raises(ReproduceError, match="min_general: only dpnv count generalisation starts"):
        run_controller("table2", "sigmoid", [0], 1, tmp_path / "t2", progress=False, min_general=300)
    # the shards (the Ray path's tasks) carry it too
    sharded = run_controller_sharded("dpnv", "sigmoid", [0, 1], 1, tmp_path / "sh", shards=2, min_general=300, **kw)
    assert sharded.extra["min_general"] == 300
    shards = sorted((tmp_path / "sh" / "shards").glob("sigmoid-*/sigmoid.ckpt"))
    assert len(shards) == 2 and all(load_checkpoint_dict(p)["identity"]["min_general"] == 300 for p in shards)
    with pytest.raises(ReproduceError, match=r"in 0\.\.625, got 700"):
        run_controller("dpnv", "sigmoid", [0], 1, tmp_path / "bad", min_general=700, **kw)


def test_the_both_poles_fitness_is_the_damping_fitness_that_sees_the_short_pole():
    assert STUDIES["dpnv"].fitnesses == FITNESSES and STUDIES["dpv"].fitnesses == ("study",)
    for kind in ("sigmoid", "snn"):
        cfg = study_config("dpnv", kind, coding="push-pull", pop_size=12)
        genomes = NEAT(cfg, seeds=[5]).ask()
        task, spec = study_task("dpnv", "push-pull"), study_spec("dpnv", kind, "push-pull")
        both = study_fitness("dpnv", kind, cfg, "push-pull", fitness="damping-both-poles")(genomes)
        direct = TaskFitness(task.with_fitness("damping-both-poles", DPNV_EPISODE_STEPS), cfg, spec)(genomes)
        assert torch.equal(both, direct), kind
        # (random genomes fall before the 100 steps from which the damping term counts, so the
        # scores match the study's here; tests/tasks/test_double_pole.py shows the terms differ)
        assert study_fitness("dpnv", kind, cfg, "push-pull").task.fitness_name == "damping"
        over_starts = study_fitness("dpnv", kind, cfg, "push-pull", fitness_starts=2, fitness="damping-both-poles")
        assert over_starts.task.fitness_name == "damping-both-poles" and over_starts.episodes == 2
    with pytest.raises(ValueError, match="only dpnv offers 'damping-both-poles'"):
        study_fitness("dpv", "sigmoid", study_config("dpv", "sigmoid"), fitness="damping-both-poles")
    with pytest.raises(ValueError, match="fitness must be one of"):
        study_fitness("dpnv", "sigmoid", study_config("dpnv", "sigmoid"), fitness="damping")


def test_reproduce_dpnv_with_the_both_poles_fitness_records_it_and_resumes_only_with_it(tmp_path):
    out = tmp_path / "both"
    kw = dict(progress=False, setup="neat-2002", ga="neat-1.2.1-dpnv-per-gene", coding="signed")
    r = run_controller("dpnv", "sigmoid", [0, 1], 8, out, fitness="damping-both-poles", **kw)
    own = run_controller("dpnv", "sigmoid", [0, 1], 8, tmp_path / "own", **kw)
    assert r.extra["fitness"] == "damping-both-poles" and own.extra["fitness"] == "study"
    # the option reaches the fitness: seed 0's best balances past the 100 steps from which the
    # damping term counts by generation 6
    assert not torch.equal(r.history, own.history)
    with pytest.raises(ReproduceError, match=r"fitness='damping-both-poles', this call asks for fitness='study'"):
        run_controller("dpnv", "sigmoid", [0, 1], 8, out, resume=True, **kw)
    # a checkpoint written before the option existed holds no fitness: it ran with the study's own
    from evolution.checkpoint import atomic_torch_save

    old = load_checkpoint_dict(tmp_path / "own" / "sigmoid.ckpt")
    del old["identity"]["fitness"]
    atomic_torch_save(old, tmp_path / "own" / "sigmoid.ckpt")
    assert run_controller("dpnv", "sigmoid", [0, 1], 8, tmp_path / "own", resume=True, **kw).history.equal(own.history)
    write_study_report({"sigmoid": r}, "dpnv", out, command="test", generalization=False)
    assert "`--fitness damping-both-poles`" in (out / "dpnv.md").read_text()
    assert json.loads((out / "summary.json").read_text())["rows"]["sigmoid"]["fitness"] == "damping-both-poles"
    assert "fitness" not in study_rows({"sigmoid": own}, "dpnv", generalization=False)["rows"]["sigmoid"]
    with pytest.raises(ReproduceError, match="'damping-both-poles' only for dpnv"):
        run_controller("table2", "sigmoid", [0], 1, tmp_path / "t2", progress=False, fitness="damping-both-poles")


def test_neat_121_presets_reach_the_study_config_through_the_registry():
    from evolution.neat121 import NEAT121_DPNV, NEAT121_DPV
    from tasks.studies.registry import GA_CHOICES, GA_PRESETS, STUDIES

    assert {"neat-1.2.1-dpv", "neat-1.2.1-dpnv"} <= set(GA_CHOICES) and dict(GA_PRESETS["neat-1.2.1-dpnv"]) == NEAT121_DPNV
    for variant, preset in (("dpv", NEAT121_DPV), ("dpnv", NEAT121_DPNV)):
        for kind in ("snn", "sigmoid"):
            cfg = STUDIES[variant].config(kind, ga=f"neat-1.2.1-{variant}", coding="signed")
            assert all(getattr(cfg, k) == v for k, v in preset.items()), (variant, kind)
            assert cfg.num_inputs == {"dpv": 6, "dpnv": 3}[variant] and cfg.num_bias == (kind == "sigmoid")
    with pytest.raises(KeyError):
        GA_PRESETS["neat-1.2.2"]


def test_the_dpnv_per_gene_pick_is_the_neat121_file_with_its_weight_rule_and_population_changed():
    from evolution.neat121 import NEAT121_DPNV, NEAT121_DPNV_PER_GENE
    from tasks.studies.registry import GA_CHOICES, STUDIES

    assert "neat-1.2.1-dpnv-per-gene" in GA_CHOICES
    changed = {k for k in NEAT121_DPNV if NEAT121_DPNV_PER_GENE[k] != NEAT121_DPNV[k]}
    assert changed | (NEAT121_DPNV_PER_GENE.keys() - NEAT121_DPNV.keys()) == {
        "pop_size", "weight_mutate_neatc", "weight_mutate_per_gene", "weight_mutate_rate", "weight_replace_rate",
        "conn_add_tries", "weight_init_uniform", "weight_init_stdev", "conn_add_shared_weight", "survival_neatc",
        "stagnation_clock_before", "compat_mutation_num", "node_add_neatc", "bias_value"}
    cfg = STUDIES["dpnv"].config("sigmoid", ga="neat-1.2.1-dpnv-per-gene", coding="signed")
    assert cfg.pop_size == 300 and cfg.weight_mutate_per_gene and not cfg.weight_mutate_neatc
    assert cfg.weight_mutate_power == NEAT121_DPNV["weight_mutate_power"] and cfg.num_inputs == 3


def test_the_dpnv_snn_pick_is_the_per_gene_pick_with_population_100():
    from evolution.neat121 import NEAT121_DPNV_PER_GENE, NEAT121_DPNV_SNN
    from tasks.studies.registry import GA_CHOICES

    assert "neat-1.2.1-dpnv-snn" in GA_CHOICES
    assert {k for k in NEAT121_DPNV_SNN if NEAT121_DPNV_SNN[k] != NEAT121_DPNV_PER_GENE.get(k)} == {"pop_size"}
    cfg = study_config("dpnv", "snn", ga="neat-1.2.1-dpnv-snn", coding="push-pull")
    assert cfg.pop_size == 100 and cfg.weight_mutate_per_gene and cfg.num_inputs == 6


def test_the_neat121_ablation_runs_each_setting_and_compares_it_to_the_preset(capsys):
    import json

    from experiments.neat121_ablation import ABLATIONS
    from experiments.neat121_ablation import main as ablation_main

    ablation_main(["dpv", "--seeds", "300-301", "--generations", "2", "--only", "preset", "exclusive"])
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [row["setting"] for row in lines] == [n for n in ABLATIONS if "preset" in n or "exclusive" in n]
    assert lines[0]["solved"].endswith("/2") and lines[1]["p_vs_preset"] <= 1.0


def test_the_multi_start_experiment_takes_either_controller_and_its_overrides(capsys):
    from experiments.dpnv_fitness_starts import main as starts_main

    starts_main(["--kind", "snn", "--seeds", "2", "--generations", "2", "--starts", "3", "--network-ms", "10",
                 "--spec", '{"neuron": {"a": 0.01}, "i_background": 40.0}', "--cfg", '{"pop_size": 16}'])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (out["kind"], out["starts"], out["generations"], out["seeds"]) == ("snn", 3, 2, "5000-5001")
    assert out["solved"] == "0/2" and len(out["best_long_steps"]) == len(out["best_held"]) == 2
    assert all(0 < s < 100_000 for s in out["best_long_steps"])  # two generations of 16 balance briefly
    with pytest.raises(ValueError, match="alpha"):  # a misspelt field of the neuron is an error, not ignored
        starts_main(["--kind", "snn", "--seeds", "1", "--generations", "1", "--spec", '{"neuron": {"alpha": 1}}'])
