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
The C takes structs declared in ``episodes.h``: the plant, the rows and the outputs
(``EpisodesIO``), and the controller's networks and constants (``SpikingParams`` from
``spiking_params``, ``SigmoidParams`` from ``sigmoid_params``).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import torch
from torch import Tensor

from evolution.ablation import StaticMapController
from evolution.input_coding import CODING_CODES, coding_constants, input_coding_of
from evolution.kernels.native_plant import native_plant
from evolution.phenotype import DECODER_CODES, SigmoidController, SpikingController, kernel_constants
from evolution.task import Task, TaskError
from snn_torch.kernels.build import KernelStruct, library_loader
from snn_torch.kernels.sigmoid import SIGMOID_MAX_NODES

__all__ = ["native_rollout", "native_episodes_available", "EpisodesIO", "SpikingParams", "SigmoidParams",
           "spiking_params", "sigmoid_params"]

_CSRC = Path(__file__).resolve().parent / "csrc"
_library = library_loader("episodes", _CSRC / "episodes.c", _CSRC / "episodes.h")


_i64, _f64, _int, _ptr = ctypes.c_int64, ctypes.c_double, ctypes.c_int, ctypes.c_void_p


class EpisodesIO(KernelStruct):
    """``episodes_io`` of ``episodes.h``: the plant, the input coding, the rows and the outputs."""
    _fields_ = [("step_fn", _ptr), ("observe_fn", _ptr), ("plant_params", _ptr), ("plant_bytes", _i64),
                ("width", _i64), ("starts", _ptr), ("start_rows", _i64), ("episodes", _i64), ("n_obs", _i64),
                ("n_act", _i64), ("max_steps", _i64), ("offset", _ptr), ("scale", _ptr), ("coding", _i64),
                ("clip", _i64), ("n_in", _i64), ("rows", _i64), ("returns", _ptr), ("steps", _ptr),
                ("error", _ptr), ("threads", _int)]


class SpikingParams(KernelStruct):
    """``spiking_params`` of ``episodes.h``: a ``SpikingController``'s networks and constants."""
    _fields_ = [("w", _ptr), ("v0", _ptr), ("u0", _ptr), ("z0", _ptr), ("n", _i64), ("iconst", _ptr),
                ("gain", _f64), ("keys", _ptr), ("w_out", _ptr), ("rest", _ptr), ("sigma", _ptr), ("window", _i64),
                ("period_s", _f64), ("substeps", _i64), ("dt", _f64), ("a", _f64), ("b", _f64), ("c", _f64),
                ("d", _f64), ("vpeak", _f64), ("decoder", _i64), ("action_max", _f64), ("threshold", _f64),
                ("settle", _i64), ("syn", _i64), ("syn_k", _f64)]


class SigmoidParams(KernelStruct):
    """``sigmoid_params`` of ``episodes.h``: a ``SigmoidController``'s networks and constants."""
    _fields_ = [("w", _ptr), ("n", _i64), ("n_bias", _i64), ("slope", _f64), ("updates", _i64),
                ("first_output", _i64), ("decoder", _i64), ("action_max", _f64), ("settle", _i64)]


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
    io = EpisodesIO(step_fn=plant.step_ptr, observe_fn=plant.observe_ptr, plant_params=plant.params.data_ptr(),
                    plant_bytes=starts.element_size(), width=plant.width, starts=starts.data_ptr(),
                    start_rows=starts.shape[0], episodes=episodes, n_obs=task.observation_size,
                    n_act=task.action_size, max_steps=max_steps, offset=offset.data_ptr(), scale=scale.data_ptr(),
                    coding=CODING_CODES[coding], clip=int(clip), n_in=controller.n_in, rows=B,
                    returns=returns.data_ptr(), steps=steps.data_ptr(), error=error.data_ptr(),
                    threads=torch.get_num_threads())
    if isinstance(controller, SpikingController):
        params, _tensors = spiking_params(controller, dtype, episodes, settle)  # the tensors live through the call
        kind = getattr(lib, f"episodes_spiking_{suffix}")(ctypes.byref(io), ctypes.byref(params))
    else:
        params, _tensors = sigmoid_params(controller, dtype, settle)
        kind = getattr(lib, f"episodes_sigmoid_{suffix}")(ctypes.byref(io), ctypes.byref(params))
    if kind:
        _raise(task, int(kind), int(error[1]), int(error[2]), episodes)
    return returns, steps


def spiking_params(controller: SpikingController, dtype: torch.dtype, episodes: int, settle: int = 0
                   ) -> tuple[SpikingParams, tuple[Tensor | None, ...]]:
    """The episode loop's parameters for ``controller``'s networks in ``dtype``, each genome's
    rows ``episodes`` consecutive rows (``settle``: ``StaticMapController``'s control steps, 0
    for the network's own), and the tensors they point into (to keep alive through the call)."""
    spec, net = controller.spec, controller.network
    k = kernel_constants(controller, dtype)
    rows = torch.arange(controller.num_genomes * episodes, dtype=torch.int64) // episodes
    v, u, z = (t.contiguous() for t in controller.initial_state(rows).neurons[:3])  # s starts at 0 in C
    keys = controller.keys.contiguous() if k.bernoulli else None
    sigma = controller.sigma.to(dtype).contiguous()
    p = net.p
    params = SpikingParams(
        w=k.w_eff.data_ptr(), v0=v.data_ptr(), u0=u.data_ptr(), z0=z.data_ptr(), n=controller.num_local,
        iconst=k.iconst.data_ptr(), gain=k.gain, keys=None if keys is None else keys.data_ptr(),
        w_out=k.w_out.data_ptr(), rest=None if k.rest is None else k.rest.data_ptr(), sigma=sigma.data_ptr(),
        window=controller.window.window, period_s=controller.window.period_s, substeps=controller.substeps,
        dt=spec.dt_ms, a=p.a, b=p.b, c=p.c, d=p.d, vpeak=p.v_peak, decoder=DECODER_CODES[spec.decoder],
        action_max=controller.action_max, threshold=float(spec.threshold), settle=settle,
        syn=int(net.syn_decay is not None), syn_k=0.0 if net.syn_decay is None else net.syn_decay)
    return params, (k.w_eff, k.iconst, k.w_out, k.rest, v, u, z, keys, sigma)


def sigmoid_params(controller: SigmoidController, dtype: torch.dtype, settle: int = 0
                   ) -> tuple[SigmoidParams, tuple[Tensor, ...]]:
    """The episode loop's parameters for ``controller``'s networks in ``dtype`` (``settle`` as
    ``spiking_params``), and the tensor they point into."""
    net, spec = controller.network, controller.spec
    w_eff = net.effective_weight(dtype).contiguous()
    params = SigmoidParams(w=w_eff.data_ptr(), n=net.num_neurons, n_bias=net.num_bias, slope=net.slope,
                           updates=spec.updates_per_step, first_output=controller.outputs[0],
                           decoder=DECODER_CODES[spec.decoder], action_max=controller.action_max, settle=settle)
    return params, (w_eff,)


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
