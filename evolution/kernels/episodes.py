"""Whole episodes in one native call: a controller's C kernel and a task's native step in one loop.

``rollout`` (``evolution.rollout``) runs one control step of the whole batch per Python
iteration: fast for a wide batch, but once most rows have failed, the few survivors of a long
episode pay Python's and torch's per-op overhead on every step (hundreds of microseconds for
one row). Where the task has a native step (``Task.native``) and the controller a C kernel (a
``SpikingController`` or ``SigmoidController`` on the CPU, or either as ``StaticMapController``'s memoryless map),
``native_rollout`` runs every row's
whole episode in C instead (``evolution/kernels/csrc/episodes.c``): observe, normalise, act, step,
accumulate, stop, take the next row; spread over ``torch.get_num_threads()`` threads, each of
which takes the next row as soon as one of its rows finishes (no thread waits for another
until the last row is done, so a busy core delays only its own rows).

The result is the torch rollout's, bit for bit (the controllers' kernels and the plant's native
step repeat the torch operations in order; ``tests/evolution/test_native_episodes.py``), so
whether a rollout ran natively changes its speed, never its answer. A bad observation or
reward (NaN, inf) raises the torch rollout's ``TaskError``. ``SNN_NEAT_NATIVE_EPISODES=0``
switches this path off (the C kernels stay on; ``SNN_NEAT_C_KERNELS=0`` switches off all C).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
from torch import Tensor

from evolution.ablation import StaticMapController
from evolution.input_coding import CODING_CODES, coding_constants, input_coding_of
from evolution.kernels.native_plant import native_plant
from evolution.phenotype import DECODER_CODES, SigmoidController, SpikingController, kernel_constants
from evolution.task import Task, TaskError
from snn_torch.kernels.build import library_loader
from snn_torch.kernels.sigmoid import SIGMOID_MAX_NODES

__all__ = ["native_rollout", "native_episodes_available"]

_CSRC = Path(__file__).resolve().parent / "csrc"
_library = library_loader("episodes", _CSRC / "episodes.c", _CSRC / "episodes.h")


ENV_SWITCH = "SNN_NEAT_NATIVE_EPISODES"  # "0": the Python loop over control steps (C kernels stay on)


def native_episodes_available() -> bool:
    """True when the episode loop compiled (once per machine), C kernels are on and
    ``SNN_NEAT_NATIVE_EPISODES`` is not ``0``."""
    return os.environ.get(ENV_SWITCH) != "0" and _library() is not None


def _controller_supported(controller) -> bool:
    if not isinstance(controller, (SpikingController, SigmoidController)):  # only these have C kernels
        return False
    dtype, device = controller.weight.dtype, controller.weight.device
    if device.type != "cpu" or dtype not in (torch.float32, torch.float64) or controller.weight.requires_grad:
        return False
    if isinstance(controller, SpikingController):
        if controller.sigma.dtype != dtype:
            return False  # the torch decoder would promote; not worth a second kernel
        probe = controller.initial_state(torch.zeros(1, dtype=torch.int64))
        return controller.network.path(probe.neurons) == "kernel"
    if isinstance(controller, SigmoidController):
        net = controller.network
        outputs = controller.outputs
        contiguous = outputs == list(range(outputs[0], outputs[0] + len(outputs)))
        return net.backend != "torch" and net.num_neurons <= SIGMOID_MAX_NODES and contiguous
    return False


def native_rollout(task: Task, controller, starts, *, episodes: int, max_steps: int):
    """``(returns [B] float64, steps [B] int64)`` of every row ``g * episodes + e`` (genome ``g``
    from start ``e``) run to the end natively, or None where this path does not apply (no native
    step for the start states' dtype, a controller without a C kernel, no compiler, C kernels
    off). ``starts``: ``[episodes, width]`` start states shared by every genome, or ``[B, width]``
    one per row, already checked by the caller."""
    if not native_episodes_available() or not isinstance(starts, Tensor) or max_steps < 1:
        return None
    lib = _library()
    settle = 0
    if isinstance(controller, StaticMapController):  # the memory ablation's memoryless map
        controller, settle = controller.controller, controller.settle_steps
    plant = native_plant(task, starts.dtype)
    G = controller.num_genomes
    B = G * episodes
    if plant is None or not plant.accepts(starts) or not _controller_supported(controller):
        return None
    dtype = controller.weight.dtype
    coding, clip = input_coding_of(controller)
    offset, scale = (t.contiguous() for t in coding_constants(*task.bounds(dtype=dtype), coding))
    starts = starts.contiguous()
    returns = torch.zeros(B, dtype=torch.float64)
    steps = torch.zeros(B, dtype=torch.int64)
    error = torch.zeros(3, dtype=torch.int64)
    suffix = "f32" if dtype == torch.float32 else "f64"
    common = (plant.step_ptr, plant.observe_ptr, plant.params.data_ptr(), starts.element_size(), plant.width,
              starts.data_ptr(), starts.shape[0], episodes, task.observation_size, task.action_size, max_steps,
              offset.data_ptr(), scale.data_ptr(), CODING_CODES[coding], int(clip), controller.n_in)
    outputs = (B, returns.data_ptr(), steps.data_ptr(), error.data_ptr(), torch.get_num_threads())
    if isinstance(controller, SpikingController):
        spec, net = controller.spec, controller.network
        k = kernel_constants(controller, dtype)
        rows = torch.arange(B, dtype=torch.int64) // episodes
        v, u, z = (t.contiguous() for t in controller.initial_state(rows).neurons[:3])  # s starts at 0 in C
        keys = controller.keys.contiguous() if k.bernoulli else None
        sigma = controller.sigma.to(dtype).contiguous()
        p = net.p
        kind = getattr(lib, f"episodes_spiking_{suffix}")(
            *common, k.w_eff.data_ptr(), v.data_ptr(), u.data_ptr(), z.data_ptr(), controller.num_local,
            k.iconst.data_ptr(), k.gain, None if keys is None else keys.data_ptr(), k.w_out.data_ptr(),
            None if k.rest is None else k.rest.data_ptr(), sigma.data_ptr(), controller.window.window,
            controller.window.period_s, controller.substeps, spec.dt_ms, p.a, p.b, p.c, p.d, p.v_peak,
            DECODER_CODES[spec.decoder], controller.action_max, float(spec.threshold), settle,
            int(net.syn_decay is not None), 0.0 if net.syn_decay is None else net.syn_decay, *outputs)
    else:
        net, spec = controller.network, controller.spec
        w_eff = net.effective_weight(dtype).contiguous()
        kind = getattr(lib, f"episodes_sigmoid_{suffix}")(
            *common, w_eff.data_ptr(), net.num_neurons, net.num_bias, net.slope, spec.updates_per_step,
            controller.outputs[0], DECODER_CODES[spec.decoder], controller.action_max, settle, *outputs)
    if kind:
        _raise(task, int(kind), int(error[1]), int(error[2]), episodes)
    return returns, steps


def _raise(task: Task, kind: int, row: int, code: int, episodes: int) -> None:
    where = f"(genome {row // episodes}, episode {row % episodes})"
    if kind == 1:
        raise TaskError(f"task {task.name!r}: observe() returned observation holding NaN or inf at 1 row(s), "
                        f"first: {where}")
    if kind == 2:
        raise TaskError(f"task {task.name!r}: step() returned reward holding NaN or inf at 1 row(s), first: {where}")
    if kind == 5:
        raise TaskError(f"task {task.name!r}: step() returned state holding NaN or inf at 1 row(s), first: {where}")
    if kind == 3:
        raise TaskError(f"task {task.name!r}: its native step returned error code {code} (rows from {where})")
    raise MemoryError("the native episode loop could not allocate its buffers")
