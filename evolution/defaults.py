"""What a task gets by default: the controller spec, NEAT's settings and the fitness episodes.

One set of defaults for every plant; what differs comes from the task itself (its control
period, observation bounds, action space, whether its starts are random). ``task_config(task,
"snn" | "sigmoid")``, ``TaskFitness(task, config, "snn" | "sigmoid")``, ``make_controller(...,
task, "snn" | "sigmoid")`` and ``snn-neat evolve ENV`` all use them; the paper's studies pin
their own settings and do not read these. docs/your-own-plant.md gives the measurement behind
each choice:

- signed input coding (each observation in [-1, 1] about the middle of its bounds);
- NEAT-SNN: at most ``NETWORK_MS_MAX`` ms of network time per control step, rates over the last
  ``RATE_WINDOW_STEPS`` control steps, counted from each neuron's rate at rest; where the task's
  observations are categories (``discrete_observations``: a grid cell, a card) that jump from
  step to step, rates over the one step, of ``RATE_WINDOW_STEPS * NETWORK_MS_MAX`` ms, so they
  are counted over as long, without mixing one step's category into the next; ``SYNAPSE``:
  synapses strong and slow enough that a hidden neuron passes its input's rate change on, twice
  the paper's background current, and each neuron starting at its own point of its firing cycle;
- sigmoid NEAT: ``SIGMOID_UPDATES`` network updates per control step, so an input crosses two
  hidden layers within the step instead of one layer per step;
- ``TASK_GA``: a hidden layer of 16 from the start, sparse per-gene weight steps, and
  neat-python's settings where this NEAT has the knob;
- ``RANDOM_START_EPISODES`` fresh episodes per genome per generation where the task's starts
  are random (``has_random_starts``), one where they are fixed.
"""

from __future__ import annotations

import math

import torch

from evolution.specs import SigmoidSpec, SpikingSpec

__all__ = ["TASK_GA", "NETWORK_MS_MAX", "RATE_WINDOW_STEPS", "SYNAPSE", "SIGMOID_UPDATES", "RANDOM_START_EPISODES",
           "default_spec", "has_random_starts", "default_episodes"]

# NEATConfig fields task_config sets before the caller's overrides: neat-python 2.0.0's defaults
# where this NEAT has the knob (the "neat-python" GA preset), the best 10 % as parents, a hidden
# layer of 16 from the start and sparse per-gene weight steps.
TASK_GA: dict = dict(
    weight_max_value=30.0, weight_min_value=-30.0, elitism=2, elitism_min_species_size=1, crossover_prob=1.0,
    interspecies_crossover_prob=0.0, max_stagnation=20, compatibility_weight_coefficient=0.5,
    compatibility_normalize_min_genes=1, survival_threshold=0.1,
    max_hidden=16, initial_hidden=16,
    weight_mutate_per_gene=True, weight_mutate_rate=0.1, weight_mutate_power=1.0, weight_replace_rate=0.01,
)
NETWORK_MS_MAX = 10.0  # ms of network time per control step at most (NEAT-SNN)
RATE_WINDOW_STEPS = 3  # control steps in NEAT-SNN's rate window
# NEAT-SNN's synapses, background and start: 30 mV per spike per unit weight spread over 10 ms
# (the paper's 1 mV in one substep moves a hidden neuron by 0.7 % of its input's rate change;
# these pass 23 % at this background), 60 mV/ms of background (more spikes per control step), and a
# "spread" start (no synchronous first volley through the strong synapses).
SYNAPSE: dict = dict(synapse_kick_mv=30.0, synapse_tau_ms=10.0, i_background=60.0, start="spread")
SIGMOID_UPDATES = 3  # sigmoid network updates per control step
RANDOM_START_EPISODES = 16  # fresh episodes per genome per generation on a task with random starts


def default_spec(task, controller: str) -> SpikingSpec | SigmoidSpec:
    """The spec of ``controller`` (``"snn"`` or ``"sigmoid"``) for ``task``: signed inputs, and
    NEAT-SNN's rates over ``RATE_WINDOW_STEPS`` control steps of at most ``NETWORK_MS_MAX`` ms of
    network time each (over one step of ``RATE_WINDOW_STEPS * NETWORK_MS_MAX`` ms where
    ``task.discrete_observations``), counted from rest, with ``SYNAPSE``'s synapses, background
    and start; sigmoid NEAT's ``SIGMOID_UPDATES`` updates per step (module docstring)."""
    if controller == "sigmoid":
        return SigmoidSpec(input_coding="signed", updates_per_step=SIGMOID_UPDATES)
    if controller != "snn":
        raise ValueError(f"controller must be 'snn' or 'sigmoid', got {controller!r}")
    if getattr(task, "discrete_observations", False):  # categories: one step's, counted as long as a window
        window, network_ms = 1, RATE_WINDOW_STEPS * NETWORK_MS_MAX
    else:
        window, network_ms = RATE_WINDOW_STEPS, _network_ms(float(task.control_period_s) * 1000.0)
    return SpikingSpec(input_coding="signed", rate_window_steps=window, rest_relative=True, network_ms=network_ms,
                       **SYNAPSE)


def _network_ms(period_ms: float) -> float | None:
    """NEAT-SNN's network time per control step of ``period_ms`` (ms): at most ``NETWORK_MS_MAX``,
    whole substeps; None for the period itself."""
    dt_ms = SpikingSpec().dt_ms
    if period_ms > NETWORK_MS_MAX:
        return NETWORK_MS_MAX
    if abs(round(period_ms / dt_ms) * dt_ms - period_ms) > 1e-9:
        # a period that is no whole number of substeps runs the whole substeps within it
        return max(1, math.floor(period_ms / dt_ms + 1e-9)) * dt_ms
    return None


def has_random_starts(task) -> bool:
    """Whether ``task.reset`` draws its start states from the generator (two generators with
    different seeds give different starts)."""
    a = task.reset(2, torch.Generator().manual_seed(1))
    b = task.reset(2, torch.Generator().manual_seed(2))
    parts_a = a if isinstance(a, tuple) else (a,)
    parts_b = b if isinstance(b, tuple) else (b,)
    return any(not torch.equal(x, y) for x, y in zip(parts_a, parts_b, strict=True))


def default_episodes(task) -> int:
    """Episodes per genome per generation: ``RANDOM_START_EPISODES`` fresh ones where the task's
    starts are random, else 1."""
    return RANDOM_START_EPISODES if has_random_starts(task) else 1
