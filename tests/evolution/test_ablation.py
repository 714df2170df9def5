"""StaticMapController: any controller of the seam as a memoryless map of its observation."""

import pytest
import torch

from evolution import NEAT
from evolution.ablation import StaticMapController
from evolution.phenotype import SigmoidSpec, make_controller
from tasks.double_pole import DoublePoleTask
from tasks.studies.double_pole import study_config, study_fitness, study_task


def _evolved(kind: str):
    cfg = study_config("dpnv", kind, pop_size=12, node_add_prob=0.5, conn_add_prob=0.5)
    neat = NEAT(cfg, seeds=[7])
    neat.run(study_fitness("dpnv", kind, cfg), 3)
    return neat.ask(), cfg


def _forces(controller, obs_a, obs_b):
    state = controller.initial_state(torch.arange(controller.num_genomes))
    first, state, _ = controller.act(obs_a, state)
    _, state, _ = controller.act(obs_b, state)
    again, _, _ = controller.act(obs_a, state)
    return first, again


@pytest.mark.parametrize("kind", ["snn", "sigmoid"])
def test_a_static_map_answers_an_observation_the_same_whatever_came_before(kind):
    genomes, cfg = _evolved(kind)
    controller = make_controller(genomes, cfg, study_task("dpnv"), kind)
    P = genomes.pop_size
    a, b = torch.tensor([[0.55, 0.45, 0.5]]).expand(P, 3), torch.tensor([[0.2, 0.9, 0.1]]).expand(P, 3)
    first, again = _forces(StaticMapController(controller, 5), a, b)
    assert torch.equal(first, again)
    first, again = _forces(controller, a, b)  # as evolved, the past changes the answer
    assert not torch.equal(first, again)


def test_a_direct_sigmoid_net_is_its_own_static_map():
    # inputs wired straight to the output, no hidden node, no self-loop: nothing to remember
    cfg = study_config("dpv", "sigmoid", pop_size=8)
    genomes = NEAT(cfg, seeds=[2]).ask()
    task = DoublePoleTask.with_velocities(max_steps=200, observation_bounds=study_task("dpv").observation_high)
    from evolution.rollout import rollout

    controller = make_controller(genomes, cfg, task, SigmoidSpec())
    as_evolved = rollout(task, controller).steps
    static = rollout(task, StaticMapController(controller, 1)).steps
    assert torch.equal(as_evolved, static) and int(as_evolved.max()) > 1
    with pytest.raises(ValueError, match="settle_steps"):
        StaticMapController(controller, 0)
