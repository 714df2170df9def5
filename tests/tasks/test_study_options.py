"""The study options as one object (``StudyOptions``), each study's setups and budgets."""

from __future__ import annotations

import dataclasses

import pytest

from evolution.checkpoint import atomic_torch_save, load_checkpoint_dict
from tasks.studies.cli import _study_options, build_parser
from tasks.studies.registry import CONTROLLERS, STUDIES, ReproduceError, StudyOptions
from tasks.studies.reproduce import run_controller


def test_with_no_options_the_double_pole_studies_run_each_controllers_best_setup():
    dpv, dpnv = STUDIES["dpv"], STUDIES["dpnv"]
    for c in CONTROLLERS:
        o = dpv.options(c)
        assert (o.setup, o.ga, o.coding, o.fitness_starts) == ("best", "tuned", "signed", 1)
    snn, sigmoid = dpnv.options("snn"), dpnv.options("sigmoid")
    assert (snn.ga, snn.coding, snn.fitness_starts, snn.fitness, snn.champion_test, snn.min_general) == (
        "neat-1.2.1-dpnv-snn", "push-pull", 4, "damping-both-poles", "species", 200)
    assert (sigmoid.ga, sigmoid.coding, sigmoid.fitness_starts, sigmoid.fitness, sigmoid.champion_test,
            sigmoid.min_general) == ("neat-1.2.1-dpnv-per-gene", "signed", 64, "study", "species", 250)
    assert dpnv.config("snn").pop_size == 100 and dpnv.config("sigmoid").pop_size == 300
    # the paper's tables have one setup, the paper's
    assert STUDIES["table2"].options("snn") == StudyOptions(setup="paper", ga="tuned", coding="study",
                                                           champion_test="champion", fitness_starts=1,
                                                           fitness="study", self_loops=False)


def test_a_setup_names_the_replications_and_a_given_field_overrides_it_for_every_controller():
    dpnv = STUDIES["dpnv"]
    for c in CONTROLLERS:
        o = dpnv.options(c, StudyOptions(setup="neat-1.2.1"))
        assert (o.ga, o.coding, o.champion_test, o.fitness_starts) == ("neat-1.2.1-dpnv", "signed", "species", 1)
        assert dpnv.config(c, StudyOptions(setup="neat-1.2.1")).pop_size == 1000
        first = dpnv.options(c, StudyOptions(setup="neat-2002"))
        assert (first.ga, first.coding, first.champion_test, first.fitness) == ("tuned", "study", "champion", "study")
        o = dpnv.options(c, StudyOptions(coding="study", min_general=300))  # the best setup, two fields overridden
        assert (o.coding, o.min_general, o.setup) == ("study", 300, "best")
        assert o.ga == dpnv.options(c).ga
    with pytest.raises(ReproduceError, match=r"setup must be one of \('best', 'neat-1.2.1', 'neat-2002'\) for dpnv"):
        dpnv.options("snn", StudyOptions(setup="paper"))
    with pytest.raises(ReproduceError, match="fitness_starts must be 1 for dpv"):
        STUDIES["dpv"].options("snn", StudyOptions(fitness_starts=4))
    with pytest.raises(ReproduceError, match="min_general: only dpnv"):
        STUDIES["table1"].options("snn", StudyOptions(min_general=300))
    with pytest.raises(ReproduceError, match="ga must be one of"):
        dpnv.options("snn", StudyOptions(ga="neat-java"))


@pytest.mark.parametrize("name", list(STUDIES))
def test_resolving_resolved_options_gives_them_back(name):
    """A shard or a Ray task resolves the options its caller resolved: nothing may move."""
    s = STUDIES[name]
    for setup in s.setups:
        for c in CONTROLLERS:
            for given in (StudyOptions(setup=setup), StudyOptions(setup=setup, self_loops=True),
                          *([StudyOptions(setup=setup, min_general=200)] if s.general_solutions else [])):
                once = s.options(c, given)
                assert s.options(c, once) == once
                assert all(v is not None for k, v in dataclasses.asdict(once).items() if k != "min_general")


def test_the_budget_is_counted_in_evaluations_for_the_double_pole():
    dpnv, dpv = STUDIES["dpnv"], STUDIES["dpv"]
    snn, sigmoid = dpnv.config("snn"), dpnv.config("sigmoid")
    assert dpnv.generations(snn) == 1000 and dpnv.generations(sigmoid) == 333  # at most 100,000 evaluations
    assert dpnv.generations(snn, evaluations=30_000) == 300 and dpnv.generations(snn, generations=7) == 7
    assert dpv.generations(dpv.config("snn")) == 100  # 15,000 evaluations of 150
    assert STUDIES["table1"].generations(STUDIES["table1"].config("snn")) == 100  # the paper's generations
    with pytest.raises(ReproduceError, match="not both"):
        dpnv.generations(snn, generations=5, evaluations=500)
    with pytest.raises(ReproduceError, match=r"at least one generation \(300 genomes\)"):
        dpnv.generations(sigmoid, evaluations=299)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["reproduce", "dpnv", "--generations", "5", "--evaluations", "500"])


def test_every_option_has_a_flag_and_an_unset_flag_leaves_the_setups_value():
    args = build_parser().parse_args(["reproduce", "dpnv"])
    assert _study_options(args) == StudyOptions()
    args = build_parser().parse_args(["reproduce", "dpnv", "--setup", "neat-1.2.1", "--fitness-starts", "3",
                                      "--self-loops", "--min-general", "250", "--champion-test", "champion",
                                      "--fitness", "damping-both-poles", "--coding", "push-pull", "--ga", "neat-c++"])
    assert _study_options(args) == StudyOptions(setup="neat-1.2.1", ga="neat-c++", coding="push-pull",
                                                champion_test="champion", fitness_starts=3,
                                                fitness="damping-both-poles", min_general=250, self_loops=True)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["reproduce", "dpnv", "--setup", "fastest"])


def test_the_identity_keeps_the_spelling_of_checkpoints_written_before_setups(tmp_path):
    """The resolved options fill the identity keys they always had: NEAT 2002's test of a solution is
    ``min_general`` None, the GA is in words; a checkpoint of the first setup resumes with it, and
    without it the error says which setup to name."""
    dpnv = STUDIES["dpnv"]
    ident = dpnv.identity("sigmoid", StudyOptions(setup="neat-2002"))
    assert ident == {"ga": "neat-python, survival_threshold=0.1", "coding": "study", "champion_test": "champion",
                     "fitness_starts": 1, "fitness": "study", "min_general": None, "self_loops": False}
    assert dpnv.identity("sigmoid")["min_general"] == 250
    assert set(StudyOptions.identity_defaults()) == set(ident)
    kw = dict(progress=False, stop_after=1)
    first = run_controller("dpv", "sigmoid", [0], 100, tmp_path, setup="neat-2002", **kw)
    checkpoint = tmp_path / "sigmoid.ckpt"
    data = load_checkpoint_dict(checkpoint)
    for key in ("coding", "champion_test", "fitness_starts", "fitness", "min_general"):  # as written before them
        del data["identity"][key]
    atomic_torch_save(data, checkpoint)
    with pytest.raises(ReproduceError, match=r"coding='study', this call asks for coding='signed'.*--setup neat-2002"):
        run_controller("dpv", "sigmoid", [0], 100, tmp_path, resume=True, **kw)
    again = run_controller("dpv", "sigmoid", [0], 100, tmp_path, resume=True, setup="neat-2002", **kw)
    assert again.extra["setup"] == "neat-2002" and again.extra["coding"] == "study"
    assert load_checkpoint_dict(checkpoint)["neat"]["generation"] == 2 and again.history[:1].equal(first.history[:1])
