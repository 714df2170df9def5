"""Phenotypes: genomes -> controllers, each ``encoder -> population network -> decoder``.

Every genome of an ``R x P`` population maps to one network of a single
``snn_torch.PopulationRecurrentIzhikevich`` (``SpikingController``) or
``snn_torch.PopulationRecurrentSigmoid`` (``SigmoidController``): the genome's enabled genes are
the mask, its weights the weights, node slot ``i`` the neuron ``i``. Only node slots that some
genome of the batch uses are simulated; every sum runs in slot order, so a genome's actions
do not depend on the batch it is evaluated in, its position in it, or the slots it simulates.

Node roles (``NEATConfig`` layout): input slots are driven by the encoder; bias slots by a
constant (a current of ``i_input_max`` for spiking networks, the value 1 for sigmoid ones);
output slots are read by the decoder; hidden slots are neurons. All of a spiking controller's
physics and coding choices live in one place, ``SpikingSpec``.

Controllers are stateless modules with the ``evolution.task.Controller`` protocol:
``initial_state(network)`` gives the state of rows mapped to networks by ``network [B]`` (several
episodes per genome), ``act(inputs, state)`` one control step from the coded observations,
``select(state, keep)`` the state of the rows kept when finished episodes are dropped.
``evolution.rollout`` drives them on any ``evolution.task.Task``.

The spec picks the controller: ``make_controller`` looks the spec's type up in ``CONTROLLERS``
(``SpikingSpec`` -> ``SpikingController``, ``SigmoidSpec`` -> ``SigmoidController``;
``register_controller`` adds one), and a name (``"snn"``, ``"sigmoid"``) stands for its spec's
defaults (``as_spec``). Each controller's encoders and decoders are modules of
``snn_torch.modules.coding``, looked up by the spec's names in ``ENCODERS`` and the decoder tables.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import torch
from torch import Tensor, nn

from evolution.config import NEATConfig
from evolution.defaults import TASK_GA, default_spec
from evolution.input_coding import inputs_per_observation
from evolution.population import Genomes
from evolution.specs import (
    DECODER_CODES,
    ENCODERS,
    NEAT_SIGMOID_SLOPE,
    SIGMOID_DECODERS,
    SPIKING_DECODERS,
    SigmoidSpec,
    SpikingSpec,
)
from snn_torch.functional.counter_rng import fnv1a_keys
from snn_torch.functional.decode import ordered_matvec
from snn_torch.functional.izhikevich import (
    IzhikevichParams,
    IzhikevichState,
    izhikevich_init,
    izhikevich_run,
)
from snn_torch.functional.recurrent import RecurrentState, SynapticState
from snn_torch.kernels.network import RateControlKernel
from snn_torch.modules.coding import (
    RateWindow,
    RateWindowState,
)
from snn_torch.modules.recurrent import PopulationRecurrentIzhikevich, PopulationRecurrentSigmoid

__all__ = ["SpikingSpec", "SigmoidSpec", "SpikingController", "SigmoidController", "SpikingState",
           "SigmoidState", "rest_rate_hz", "rest_cycle", "spread_phases", "used_slots", "local_slots", "NEAT_SIGMOID_SLOPE", "ENCODERS", "SPIKING_DECODERS",
           "SIGMOID_DECODERS", "make_controller", "spiking_config", "SPIKING_SIGMA", "sigmoid_config", "task_config",
           "as_spec", "spec_name", "check_controller_config", "CONTROLLERS", "CONTROLLER_NAMES", "register_controller",
           "network_inputs"]

@functools.lru_cache(maxsize=32)
def rest_rate_hz(neuron: IzhikevichParams, current: float, dt_ms: float) -> float:
    """Steady firing rate (Hz) of one neuron under a constant ``current`` (mV/ms): spikes in 2 s
    after 1 s of settling, integrated as the networks are (Heun, sub-step reset, float64)."""
    steps = int(round(3000.0 / dt_ms))
    v, u = izhikevich_init((1,), neuron, dtype=torch.float64)
    z, _ = izhikevich_run(torch.full((steps, 1), float(current), dtype=torch.float64),
                          IzhikevichState(v, u), neuron, dt_ms=dt_ms)
    return float(z[steps // 3:].sum()) / 2.0


@functools.lru_cache(maxsize=32)
def rest_cycle(neuron: IzhikevichParams, current: float, dt_ms: float) -> tuple[Tensor, Tensor]:
    """One neuron's states under a constant ``current`` (mV/ms) after 1 s of settling: ``v`` (mV)
    and ``u`` (mV/ms), float64 ``[K]``, at ``K`` consecutive substeps spanning one interspike
    interval (``K = 1`` where it does not fire). Integrated as the networks are."""
    settle = int(round(1000.0 / dt_ms))
    v, u = izhikevich_init((1,), neuron, dtype=torch.float64)
    drive = torch.full((settle, 1), float(current), dtype=torch.float64)
    _, state = izhikevich_run(drive, IzhikevichState(v, u), neuron, dt_ms=dt_ms)
    rate = rest_rate_hz(neuron, current, dt_ms)
    k = 1 if rate <= 0.0 else max(1, int(round(1000.0 / (rate * dt_ms))))
    vs, us = [state.v], [state.u]
    for _ in range(k - 1):
        _, state = izhikevich_run(drive[:1], state, neuron, dt_ms=dt_ms)
        vs.append(state.v)
        us.append(state.u)
    return torch.cat(vs), torch.cat(us)


def spread_phases(slots: Tensor, k: int) -> Tensor:
    """Each node slot's point (an index below ``k``) in its neuron's firing cycle at the start:
    the fractional part of ``slot`` times the golden ratio, so neighbouring slots lie apart and
    a node starts at the same point in any batch. ``slots`` < 0 (padding) get 0."""
    golden = (5 ** 0.5 - 1) / 2
    phase = torch.remainder(slots.clamp(min=0).to(torch.float64) * golden, 1.0)
    return (phase * k).floor().to(torch.int64).clamp(max=k - 1)


# The decoder gain sigma scales sum_i w_i r_i (Hz): 0.005 keeps a sigmoid force off saturation at
# ~100 Hz; its mutation, bounds and weight in the distance to match ([Qiu19] evolves sigma).
SPIKING_SIGMA = dict(sigma_init_mean=0.005, sigma_mutate_power=0.00125, sigma_min_value=1e-5, sigma_max_value=1.0,
                     compatibility_sigma_coefficient=100.0)


def spiking_config(num_inputs: int, num_outputs: int = 1, **overrides) -> NEATConfig:
    """A ``NEATConfig`` for NEAT-SNN on a task with ``num_inputs`` observations and ``num_outputs``
    actions: no bias inputs, and the decoder gain's settings (``SPIKING_SIGMA``); ``overrides``
    set any other field."""
    return NEATConfig(**{"num_inputs": num_inputs, "num_outputs": num_outputs, "num_bias": 0, **SPIKING_SIGMA,
                         **overrides})


def sigmoid_config(num_inputs: int, num_outputs: int = 1, **overrides) -> NEATConfig:
    """A ``NEATConfig`` for sigmoid NEAT on a task with ``num_inputs`` observations and
    ``num_outputs`` actions: one bias input, and the decoder gain sigma (which a sigmoid
    controller does not have) frozen and out of the compatibility distance; ``overrides`` set
    any other field."""
    return NEATConfig(**{"num_inputs": num_inputs, "num_outputs": num_outputs, "num_bias": 1, "sigma_mutate_rate": 0.0,
                         "sigma_init_stdev": 0.0, "compatibility_sigma_coefficient": 0.0, **overrides})


def as_spec(spec: SpikingSpec | SigmoidSpec | str | None = None, task=None):
    """The spec a controller is made from: a spec as it is; a name of ``CONTROLLER_NAMES``
    (``"snn"``, ``"sigmoid"``) for the defaults for ``task`` (``evolution.defaults.default_spec``:
    signed inputs, and what the task's control period asks), or that spec type's own defaults
    without a task; None for ``SpikingSpec()``. Anything else is a ``ValueError`` naming the choices."""
    if spec is None:
        return SpikingSpec()
    if isinstance(spec, str):
        if spec not in CONTROLLER_NAMES:
            raise ValueError(f"a controller name must be one of {tuple(CONTROLLER_NAMES)}, got {spec!r}")
        if task is not None and spec in ("snn", "sigmoid"):
            return default_spec(task, spec)
        return CONTROLLER_NAMES[spec]()
    if type(spec) not in CONTROLLERS:
        raise ValueError(f"spec must be one of {[t.__name__ for t in CONTROLLERS]} or a name of "
                         f"{tuple(CONTROLLER_NAMES)}, got {type(spec).__name__}")
    return spec


def spec_name(spec) -> str:
    """The controller's name for a spec (``"snn"`` for a ``SpikingSpec``), or its type's name."""
    spec = as_spec(spec)
    return next((name for name, t in CONTROLLER_NAMES.items() if type(spec) is t), type(spec).__name__)


def task_config(task, spec: SpikingSpec | SigmoidSpec | str | None = "snn", **overrides) -> NEATConfig:
    """A ``NEATConfig`` for the controller of ``spec`` (a spec, or its name ``"snn"`` / ``"sigmoid"``,
    which stands for the task's default spec, ``as_spec``) on ``task`` (an ``evolution.Task``): its
    inputs and outputs from the task's observations (as the spec codes them) and actions, the
    defaults that learn on plants in general (``evolution.defaults.TASK_GA``: a hidden layer of 16
    from the start, sparse per-gene weight steps, ...), then ``spiking_config`` or
    ``sigmoid_config``; ``overrides`` set any other field."""
    spec = as_spec(spec, task)
    make = sigmoid_config if isinstance(spec, SigmoidSpec) else spiking_config
    fields = {**TASK_GA, **overrides}
    if "initial_hidden" not in overrides:  # a smaller max_hidden asked for caps the start's hidden layer
        fields["initial_hidden"] = min(fields["initial_hidden"], fields["max_hidden"])
    return make(network_inputs(task, spec), task.action_size, **fields)


def network_inputs(task, spec: SpikingSpec | SigmoidSpec | None) -> int:
    """Input nodes a controller with ``spec`` needs for ``task``'s observations (two per variable
    under the push-pull coding)."""
    return task.observation_size * inputs_per_observation(getattr(spec, "input_coding", "unit"))


def check_controller_config(config: NEATConfig, task, spec: SpikingSpec | SigmoidSpec | str | None = None) -> None:
    """``ValueError`` naming the field where ``config`` cannot serve the controller of ``spec`` on
    ``task``: inputs and outputs other than the task's observations (as the spec codes them) and
    actions, or, for sigmoid NEAT, a decoder gain sigma that varies and counts in the
    compatibility distance (a sigmoid controller has no gain, so it would split species over a
    gene with no effect)."""
    spec = as_spec(spec, task)
    inputs = network_inputs(task, spec)
    if config.num_inputs != inputs or config.num_outputs != task.action_size:
        coded = "" if inputs == task.observation_size else f" (coded as {inputs} inputs)"
        raise ValueError(f"task {task.name!r} has {task.observation_size} observations{coded} and "
                         f"{task.action_size} actions, but the config has num_inputs={config.num_inputs} and "
                         f"num_outputs={config.num_outputs} (task_config(task, spec) makes a matching one)")
    sigma_varies = config.sigma_mutate_rate > 0 or config.sigma_init_stdev > 0
    if isinstance(spec, SigmoidSpec) and sigma_varies and config.compatibility_sigma_coefficient > 0:
        raise ValueError(f"config.compatibility_sigma_coefficient = {config.compatibility_sigma_coefficient:g} "
                         f"weighs the decoder gain sigma in the compatibility distance and sigma varies "
                         f"(sigma_mutate_rate = {config.sigma_mutate_rate:g}, sigma_init_stdev = "
                         f"{config.sigma_init_stdev:g}), but a sigmoid controller has no decoder gain: set them "
                         "to 0 (sigmoid_config or task_config(task, 'sigmoid') does; is this a spiking config?)")


def used_slots(genomes: Genomes) -> Tensor:
    """Node slots some genome of the batch uses (inputs, bias and outputs always), ascending."""
    N = genomes.num_nodes
    return torch.nonzero(genomes.node.reshape(-1, N).any(0)).flatten()


def _check_layout(config: NEATConfig, genomes: Genomes, observation_size: int, action_size: int,
                  coding: str = "unit") -> None:
    inputs = observation_size * inputs_per_observation(coding)
    if config.num_inputs != inputs or config.num_outputs != action_size:
        coded = "" if inputs == observation_size else f" (coded {coding!r}: {inputs} inputs)"
        raise ValueError(f"the task has {observation_size} observations{coded} and {action_size} actions, but the "
                         f"config has num_inputs={config.num_inputs} and num_outputs={config.num_outputs}")
    if genomes.num_nodes != config.num_nodes:
        raise ValueError(f"genomes have {genomes.num_nodes} node slots, the config {config.num_nodes}")


def local_slots(genomes: Genomes) -> Tensor:
    """``[G, n]`` int64: the node slots each (flattened) genome uses, ascending, padded with -1 to
    ``n``, the most any genome uses. Inputs, bias and outputs come first in every genome."""
    N = genomes.num_nodes
    node = genomes.node.reshape(-1, N)
    n = int(node.sum(1).max()) if node.shape[0] else 0
    order = torch.argsort((~node).to(torch.int8), dim=1, stable=True)[:, :n]  # used slots first, in slot order
    return torch.where(torch.gather(node, 1, order), order, -1)


class _Phenotype(nn.Module):
    """What both controllers share: each genome's own nodes, its weights over them, the outputs.

    Network ``g`` simulates only the nodes genome ``g`` uses, in slot order (``node_slots[g]``),
    padded to the largest genome's count with nodes that have no synapses: a batch of genomes
    from many runs, whose hidden nodes sit in different slots, costs what its largest genome
    does, not the union of their slots. A sum over a genome's nodes meets the same terms in the
    same order as over its slots (and exact zeros for the rest), so results do not depend on it.
    """

    def __init__(self, genomes: Genomes, config: NEATConfig, observation_size: int, action_size: int,
                 coding: str = "unit") -> None:
        super().__init__()
        _check_layout(config, genomes, observation_size, action_size, coding)
        N = genomes.num_nodes
        self.config = config
        self.num_genomes = genomes.num_runs * genomes.pop_size
        self.nodes = used_slots(genomes)  # slots some genome uses (the columns of a single genome's activity)
        fixed = config.first_hidden
        if not bool(genomes.node.reshape(-1, N)[:, :fixed].all()):
            raise ValueError("every genome must hold its input, bias and output nodes (node[..., :first_hidden])")
        self.node_slots = slots = local_slots(genomes)  # [G, n]
        G, n = slots.shape
        self.num_local = n
        valid = slots >= 0
        at = slots.clamp(min=0)
        W = genomes.weight.reshape(-1, N, N)
        E = genomes.enabled.reshape(-1, N, N)
        pick = lambda t: t.gather(1, at.unsqueeze(-1).expand(G, n, N)).gather(2, at.unsqueeze(1).expand(G, n, n))  # noqa: E731
        self.weight = pick(W)
        self.mask = pick(E) & valid.unsqueeze(-1) & valid.unsqueeze(1)
        self.sigma = genomes.sigma.reshape(-1)
        self.outputs = [config.first_output + k for k in range(action_size)]  # the same place in every genome
        self.n_in, self.n_bias = config.num_inputs, config.num_bias

    @property
    def dtype(self) -> torch.dtype:
        """The dtype the controller computes in (its weights')."""
        return self.weight.dtype

    @property
    def device(self) -> torch.device:
        return self.weight.device

    @property
    def input_coding(self) -> tuple[str, bool]:
        """``(coding, clip)``: how the rollout codes observations for it (``evolution.input_coding``)."""
        return self.spec.input_coding, self.spec.clip_inputs

    def _check_network(self, network: Tensor) -> Tensor:
        if not isinstance(network, Tensor) or network.dim() != 1 or network.dtype != torch.int64:
            raise ValueError("network must be a [B] int64 tensor of genome indices")
        return network


class SpikingState(NamedTuple):
    """Per-row state of a ``SpikingController`` (every tensor has the rows first, but ``window``'s
    history, which has them second)."""

    network: Tensor  # [B] int64: the genome of each row
    neurons: RecurrentState | SynapticState  # [B, n]
    window: RateWindowState  # history [W, B, n]
    w_out: Tensor  # [B, n, K]: weights into the output nodes
    sigma: Tensor  # [B]
    keys: Tensor | None  # [B] int64: the Bernoulli encoder's stream of each row


class SpikingController(_Phenotype):
    """NEAT-SNN: ``encoder -> PopulationRecurrentIzhikevich -> rate window -> decoder`` for every genome.

    Args:
        genomes: the ``R x P`` population; network ``g`` is flattened genome ``g = r * P + p``.
        config: its layout (inputs = observations, outputs = actions).
        spec: physics and coding (``SpikingSpec``).
        period_s: the control period (s); action_max: actions lie in ``[-action_max, action_max]``.
        observation_size, action_size: the task's (checked against the config).
        backend: the network's ``control_step`` backend (``"auto"``: C kernel on the CPU, compiled on CUDA).
    """

    def __init__(self, genomes: Genomes, config: NEATConfig, spec: SpikingSpec | None = None, *, period_s: float,
                 action_max: float, observation_size: int, action_size: int = 1, backend: str = "auto") -> None:
        spec = SpikingSpec() if spec is None else spec
        super().__init__(genomes, config, observation_size, action_size, spec.input_coding)
        self.spec = spec
        self.substeps = spec.substeps(period_s)
        self.network = PopulationRecurrentIzhikevich(
            self.weight, self.mask, spec.neuron, i_background=spec.i_background, synapse_kick_mv=spec.synapse_kick_mv,
            synapse_tau_ms=spec.synapse_tau_ms, dt_ms=spec.dt_ms, backend=backend)
        n = self.num_local
        w_plain = torch.where(self.mask, self.weight, torch.zeros((), dtype=self.weight.dtype, device=self.weight.device))
        self.w_out = w_plain[:, :, self.outputs]  # [G, n, K], the genomes' weights (not kick-scaled)
        self.encoder: nn.Module = ENCODERS[spec.encoder](spec, self.substeps)
        self.keys = None
        if spec.encoder == "bernoulli":
            N = genomes.num_nodes
            # The genome's full weights: the same key in any batch, whatever slots it simulates.
            self.keys = fnv1a_keys(genomes.effective_weight().reshape(-1, N, N))
        self.window = RateWindow(spec.rate_window_steps, period_s)
        self._start = None  # "spread": each local node's v and u at the start, [2, G, n]
        if spec.start == "spread":
            cycle = torch.stack(rest_cycle(spec.neuron, spec.i_background, spec.dt_ms)).to(self.weight)  # [2, K]
            self._start = cycle[:, spread_phases(self.node_slots, cycle.shape[1])]
        self.rest = None
        if spec.rest_relative:
            rest = torch.full((n,), rest_rate_hz(spec.neuron, spec.i_background, spec.dt_ms), dtype=torch.float64)
            middle = 0.5 if spec.input_coding == "unit" else 0.0  # the input at the middle of the range
            rest[: self.n_in] = (middle * spec.input_rate_max_hz if spec.encoder == "bernoulli" else
                                 rest_rate_hz(spec.neuron, spec.i_background + middle * spec.i_input_max, spec.dt_ms))
            self.rest = rest.to(device=self.weight.device, dtype=self.weight.dtype)  # [n]
        self.action_max = float(action_max)
        self.decoder: nn.Module = SPIKING_DECODERS[spec.decoder](self.action_max, spec)
        # input and bias currents of each control step: [n] buffer, bias slots at i_input_max
        self._bias = torch.zeros(n, dtype=self.weight.dtype, device=self.weight.device)
        self._bias[self.n_in : self.n_in + self.n_bias] = spec.i_input_max * config.bias_value
        self._kernel: _BoundKernel | None = None  # the C kernel's constants, bound at its first step

    @classmethod
    def for_task(cls, genomes: Genomes, config: NEATConfig, task, spec: SpikingSpec, *,
                 backend: str = "auto") -> SpikingController:
        """The controller of ``genomes`` for ``task``'s observations, actions and control period."""
        return cls(genomes, config, spec, period_s=spec.period_s(task.control_period_s), action_max=task.action_max,
                   observation_size=task.observation_size, action_size=task.action_size, backend=backend)

    def initial_state(self, network: Tensor) -> SpikingState:
        network = self._check_network(network)
        B, n = network.shape[0], self.num_local
        v = torch.empty(B, n, dtype=self.weight.dtype, device=self.weight.device)
        neurons = self.network.initial_state(v)
        if self._start is not None:
            neurons = neurons._replace(v=self._start[0][network], u=self._start[1][network])
        keys = None if self.keys is None else self.keys.to(network.device)[network]
        return SpikingState(network, neurons, self.window.initial_state(v), self.w_out[network], self.sigma[network],
                            keys)

    def select(self, state: SpikingState, keep: Tensor) -> SpikingState:
        """The state of rows ``keep`` (int64 indices), in that order."""
        neurons = type(state.neurons)(*(t[keep] for t in state.neurons))
        window = RateWindowState(state.window.history[:, keep], state.window.steps)
        return SpikingState(state.network[keep], neurons, window, state.w_out[keep], state.sigma[keep],
                            None if state.keys is None else state.keys[keep])

    def act(self, obs01: Tensor, state: SpikingState) -> tuple[Tensor, SpikingState, Tensor]:
        """One control step from normalised observations ``[B, num_inputs]``: ``(action [B, K],
        state, spike counts [B, n])``. ``state`` is consumed: its tensors may be updated in place
        (the C kernel and the rate window write into them); ``select`` or a clone keeps a copy."""
        B, n, n_in = obs01.shape[0], self.num_local, self.n_in
        obs01 = obs01 if obs01.dtype == self.weight.dtype else obs01.to(self.weight.dtype)
        if self.network.path(state.neurons) == "kernel":
            return self._act_kernel(obs01.contiguous(), state)
        source = None
        # forward(), not __call__: the module hooks cost more than the ops on a small batch
        if self.keys is None:
            drive_in = self.encoder.forward(obs01)
            i_ext = torch.cat([drive_in, self._bias[n_in:].expand(B, n - n_in)], dim=1)
        else:
            source = self.encoder.forward(obs01, state.keys, state.window.steps)
            i_ext = self._bias.expand(B, n)
        counts, neurons = self.network.control_step(i_ext, state.neurons, substeps=self.substeps,
                                                    network=state.network, source_spikes=source, inplace=True)
        rates, window = self.window.forward(counts, state.window)
        drive = _weighted_drive(rates, state.w_out, self.rest)
        return self._decode(drive, state.sigma), state._replace(neurons=neurons, window=window), counts

    def _decode(self, drive: Tensor, sigma: Tensor) -> Tensor:
        decoder = self.spec.decoder
        if decoder == "sigmoid_force":
            return self.decoder.forward(drive, sigma.unsqueeze(-1))
        if decoder == "bang_bang":
            return self.decoder.forward(drive)
        return self.decoder.forward(sigma.unsqueeze(-1) * drive)

    def _act_kernel(self, obs01: Tensor, state: SpikingState) -> tuple[Tensor, SpikingState, Tensor]:
        """``act`` as one C call (encoder, network, rate window, readout; the same bits as the
        modules): on the CPU a control step's cost is mostly per-op overhead otherwise."""
        neurons, window, network = state.neurons, state.window, state.network
        B, n = neurons.v.shape
        if obs01.shape != (B, self.n_in):
            raise ValueError(f"observations must be [{B}, {self.n_in}], got {tuple(obs01.shape)}")
        self.network.check_network_once(network, B)  # the kernel reads weights by it
        if not (all(t.is_contiguous() for t in neurons) and window.history.is_contiguous()):
            neurons = type(neurons)(*(t.contiguous() for t in neurons))
            window = RateWindowState(window.history.contiguous(), window.steps)
        kernel = self._kernel
        if kernel is None or kernel.dtype != neurons.v.dtype:  # constants bound once, not every step
            kernel = self._kernel = _bind_kernel(self, neurons.v.dtype)
        steps = window.steps + 1
        drive, counts = kernel.fn(obs01, neurons, network, state.keys, window.steps * kernel.draws_per_step,
                                  window.history, window.steps % kernel.window,
                                  min(steps, kernel.window) * kernel.period_s)
        window = RateWindowState(window.history, steps)
        if state.sigma.dtype != drive.dtype:  # a gain of another dtype promotes: the torch decoder
            return self._decode(drive, state.sigma), state._replace(neurons=neurons, window=window), counts
        action = kernel.fn.decode(drive, state.sigma.contiguous(), DECODER_CODES[self.spec.decoder], self.action_max,
                                  self.spec.threshold)
        return action, state._replace(neurons=neurons, window=window), counts


class _BoundKernel(NamedTuple):
    """A controller's ``RateControlKernel`` for one dtype, and the window's constants."""

    fn: RateControlKernel
    dtype: torch.dtype
    window: int
    period_s: float
    draws_per_step: int  # Bernoulli counters per control step


class KernelConstants(NamedTuple):
    """What a spiking controller's C kernels need, in one dtype: effective weights ``[G, n, n]``,
    every node's constant current ``iconst [n]`` (mV/ms: the bias nodes' plus the background),
    the encoder's ``gain`` (current: mV/ms at input 1; Bernoulli: spike probability per substep at
    input 1), readout weights ``w_out [G, n, K]`` and ``rest [n]`` rates (Hz) or None."""

    w_eff: Tensor
    iconst: Tensor
    gain: float
    bernoulli: bool
    w_out: Tensor
    rest: Tensor | None


def kernel_constants(controller: SpikingController, dtype: torch.dtype) -> KernelConstants:
    """The controller's ``KernelConstants`` in ``dtype`` (contiguous): the control step's kernel
    (``RateControlKernel``) and the episode loop (``evolution.kernels.episodes``) bind the same ones."""
    net, spec = controller.network, controller.spec
    bernoulli = spec.encoder == "bernoulli"
    iconst = (controller._bias + net.i_background).to(dtype)
    return KernelConstants(net.effective_weight(dtype).contiguous(), iconst,
                           controller.encoder.p_max if bernoulli else spec.i_input_max, bernoulli,
                           controller.w_out.to(dtype).contiguous(),
                           None if controller.rest is None else controller.rest.to(dtype))


def _bind_kernel(controller: SpikingController, dtype: torch.dtype) -> _BoundKernel:
    net, spec = controller.network, controller.spec
    k = kernel_constants(controller, dtype)
    fn = RateControlKernel(k.w_eff, net.p, dt_ms=spec.dt_ms, substeps=controller.substeps, gain=k.gain,
                           bernoulli=k.bernoulli, iconst=k.iconst, w_out=k.w_out, rest=k.rest, syn_decay=net.syn_decay)
    return _BoundKernel(fn, dtype, controller.window.window, controller.window.period_s,
                        controller.substeps * controller.n_in)


def _weighted_drive(rates: Tensor, w_out: Tensor, rest: Tensor | None) -> Tensor:
    """``d[b, k] = sum_j w_out[b, j, k] (r[b, j] - rest[j])`` in slot order (float64 accumulator)."""
    return ordered_matvec(rates if rest is None else rates - rest, w_out)


class SigmoidState(NamedTuple):
    network: Tensor  # [B] int64
    values: Tensor  # [B, n] node values


class SigmoidController(_Phenotype):
    """Sigmoid NEAT: ``PopulationRecurrentSigmoid`` (inputs clamped to the normalised observations,
    bias nodes to 1, state carried across control steps) -> decoder, for every genome."""

    def __init__(self, genomes: Genomes, config: NEATConfig, spec: SigmoidSpec | None = None, *, action_max: float,
                 observation_size: int, action_size: int = 1, period_s: float | None = None,
                 backend: str = "auto") -> None:
        spec = SigmoidSpec() if spec is None else spec
        super().__init__(genomes, config, observation_size, action_size, spec.input_coding)
        self.spec = spec
        if config.bias_value != 1.0:  # the bias nodes stay at 1; their weights carry the value (same products)
            self.weight = self.weight.clone()
            self.weight[:, self.n_in:self.n_in + self.n_bias] *= config.bias_value
        self.network = PopulationRecurrentSigmoid(self.weight, self.mask, num_clamped=self.n_in, num_bias=self.n_bias,
                                                  slope=spec.slope, backend="auto" if backend == "compiled" else backend)
        self.action_max = float(action_max)
        self.decoder: nn.Module = SIGMOID_DECODERS[spec.decoder](self.action_max, spec)

    @classmethod
    def for_task(cls, genomes: Genomes, config: NEATConfig, task, spec: SigmoidSpec, *,
                 backend: str = "auto") -> SigmoidController:
        """The controller of ``genomes`` for ``task``'s observations and actions."""
        return cls(genomes, config, spec, action_max=task.action_max, observation_size=task.observation_size,
                   action_size=task.action_size, backend=backend)

    def initial_state(self, network: Tensor) -> SigmoidState:
        network = self._check_network(network)
        return SigmoidState(network, self.network.initial_state(network.shape[0]))

    def select(self, state: SigmoidState, keep: Tensor) -> SigmoidState:
        return SigmoidState(state.network[keep], state.values[keep])

    def act(self, obs01: Tensor, state: SigmoidState) -> tuple[Tensor, SigmoidState, Tensor]:
        y = self.network.control_step(obs01.to(self.weight.dtype), state.values, updates=self.spec.updates_per_step,
                                      network=state.network)
        return self.decoder.forward(y[:, self.outputs]), SigmoidState(state.network, y), y


# The spec picks the controller: spec type -> the controller class it makes, built by
# ``cls.for_task(genomes, config, task, spec, backend=...)``; a name -> its spec type (defaults).
CONTROLLERS: dict[type, type] = {SpikingSpec: SpikingController, SigmoidSpec: SigmoidController}
CONTROLLER_NAMES: dict[str, type] = {"snn": SpikingSpec, "sigmoid": SigmoidSpec}


def register_controller(spec_type: type, controller_type: type, name: str | None = None) -> None:
    """Make ``make_controller`` build ``controller_type.for_task(genomes, config, task, spec,
    backend=...)`` for a spec of ``spec_type`` (and ``as_spec(name)`` give ``spec_type()``). The
    controller must satisfy ``evolution.task.Controller``."""
    if not isinstance(spec_type, type) or not callable(getattr(controller_type, "for_task", None)):
        raise ValueError("register_controller takes a spec class and a controller class with a for_task() "
                         "classmethod")
    CONTROLLERS[spec_type] = controller_type
    if name is not None:
        CONTROLLER_NAMES[name] = spec_type


def make_controller(genomes: Genomes, config: NEATConfig, task, spec: SpikingSpec | SigmoidSpec | str | None = None,
                    *, backend: str = "auto"):
    """The controller of every genome for ``task`` (an ``evolution.task.Task``), of the spec's
    type (``CONTROLLERS``): a ``SpikingController`` for a ``SpikingSpec``, a ``SigmoidController``
    for a ``SigmoidSpec``; a name (``"snn"``, ``"sigmoid"``) means its spec's defaults, None
    ``SpikingSpec()`` (``as_spec``)."""
    spec = as_spec(spec, task)
    return CONTROLLERS[type(spec)].for_task(genomes, config, task, spec, backend=backend)
