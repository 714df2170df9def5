"""Controllers for the paper's cart-pole tasks, and the closed loop that evaluates them.

Every gap the paper leaves is chosen once, here, in ``SpikingSpec`` and ``MarkovSpikingSpec``
(spiking controllers) and ``SigmoidSpec`` (the sigmoid NEAT baselines), with the reason
beside each value.

Non-Markov task (Table II), NEAT-SNN: x and theta are normalised to [0, 1] over the failure
limits and injected as currents into the two input neurons; every neuron gets a background
current; the force is ``F = 10 (2 sigmoid(sigma * sum_i w_i r_i) - 1)`` over the neurons i
wired to the output node, with ``r_i`` their firing rates (Hz) over the last few control
steps and ``sigma`` evolved per genome.

Markov task (Table I), NEAT-SNN (``MarkovSpikingSpec``): the four state variables drive
four Bernoulli spike sources; the output node decodes as in Table II, from the rates of the
nodes wired to it taken relative to their rates at rest, with a bang-bang force
``F = +-10 N`` on the sign of ``sum_i w_i (r_i - r_rest,i)``.

Sigmoid NEAT (baseline): the same normalised inputs plus a bias input, a recurrent sigmoid
network updated once per control step (state carried across steps, NEAT's usual setting
for pole balancing), ``F = 10 (2 y - 1)`` from the output ``y`` in (0, 1) (Table I:
``F = +-10 N`` on ``y > 0.5``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.phenotype import NEAT_SIGMOID_SLOPE
from evolution.population import Genomes
from snn_torch.compiled import CompiledSubstep, eager_substep
from snn_torch.functional.fused_cpu import fused_recurrent_izhikevich_steps
from snn_torch.functional.fused_cpu import supports as fused_supports
from snn_torch.functional.izhikevich import (
    QIU2019,
    IzhikevichParams,
    IzhikevichState,
    check_dt,
    izhikevich_init,
    izhikevich_run,
)
from snn_torch.functional.recurrent import recurrent_init, recurrent_izhikevich_step
from tasks.cartpole import (
    DEFAULT_PLANT,
    THETA,
    THETA_DOT,
    X_DOT,
    CartPoleParams,
    X,
    cartpole_failed,
    cartpole_step,
    check_state,
)
from tasks.counter_rng import fnv1a_keys, mix64, uniform01
from tasks.fused_loop import (
    MAX_NODES,
    MAX_WINDOW,
    genome_keys,
    loop_available,
    markov_spiking_loop,
    sigmoid_loop,
    spiking_loop,
)

__all__ = ["SpikingSpec", "SigmoidSpec", "MarkovSpikingSpec", "SpikingPolicy", "SigmoidPolicy", "MarkovSpikingPolicy",
           "closed_loop", "normalized_inputs", "markov_limits", "MARKOV_OBSERVE"]


@dataclass(frozen=True)
class SpikingSpec:
    """The spiking controller's free choices (the paper gives none of these values)."""

    neuron: IzhikevichParams = QIU2019  # [Qiu19] Fig. 2's neuron for every node
    dt_ms: float = 0.5  # snn_torch's validated default: rates within 3 Hz + 5 % of a fine reference
    # mV/ms (nA) into every neuron: alone, a neuron fires at ~270 Hz (Fig. 2's f-I curve), high on
    # the curve, so inhibitory input lowers its rate instead of silencing it ([Qiu19]'s "frequency
    # sufficiency"). The choice that mattered most: tuning seeds 5000-5031, 100 generations, all 32
    # runs solved for every value from 20 to 60 nA (medians 11-13 generations); at 5 nA 5/16 runs
    # solved within 60 generations and at 0 nA none (README, "Choices and their sensitivity").
    i_background: float = 30.0
    # mV/ms added to an input neuron at normalised input 1 (~270 -> ~700 Hz with the background).
    i_input_max: float = 60.0
    rate_window_steps: int = 4  # control steps in the firing-rate window (40 ms at tau = 10 ms)
    # mV jump of the postsynaptic membrane per presynaptic spike per unit weight: a spike drives
    # w * kick / dt_ms for one substep, so the kick does not depend on dt (Izhikevich 2003's networks
    # add w to I for one 1 ms step: a w mV kick). With NEAT's weights (|w| <= 8) a few coincident
    # spikes fire a neuron, the paper's "cluster of incoming spikes".
    synapse_kick_mv: float = 1.0

    def __post_init__(self) -> None:
        check_dt(self.dt_ms)
        for name in ("i_background", "i_input_max", "synapse_kick_mv"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"SpikingSpec.{name} must be finite, got {value!r}")
        if self.rate_window_steps < 1:
            raise ValueError(f"SpikingSpec.rate_window_steps must be >= 1, got {self.rate_window_steps}")


@dataclass(frozen=True)
class SigmoidSpec:
    """The sigmoid baseline's free choices."""

    updates_per_step: int = 1  # network updates per control step (NEAT pole balancing: 1)


def _sigmoid(x: Tensor) -> Tensor:
    # torch.sigmoid's vectorised and scalar-tail paths differ in the last bit, so a row's
    # result would depend on its position in the batch; this form does not.
    return 1.0 / (1.0 + torch.exp(-x))


def normalized_inputs(state: Tensor, p: CartPoleParams, observe: tuple[int, ...] = (X, THETA),
                      limits: tuple[float, ...] | None = None) -> Tensor:
    """State variables ``observe`` mapped from [-limit, limit] to [0, 1] (clamped), ``[..., len(observe)]``.

    Default: x and theta over the failure limits (the non-Markov inputs).
    """
    limits = (p.x_limit, p.theta_limit) if limits is None else limits
    cols = [(state[..., k] / lim + 1.0) * 0.5 for k, lim in zip(observe, limits, strict=True)]
    return torch.stack(cols, -1).clamp(0.0, 1.0)


class SpikingPolicy:
    """NEAT-SNN for the non-Markov task: one batched recurrent Izhikevich network."""

    def __init__(self, genomes: Genomes, config: NEATConfig, spec: SpikingSpec, tau_s: float,
                 plant: CartPoleParams, *, use_fused: bool = True, compile_step: bool | None = None) -> None:
        """``compile_step``: run the torch path's substeps through ``torch.compile``
        (``snn_torch.compiled.CompiledSubstep``; the same results, fused kernels); by default
        on CUDA only. Where the C kernels run (CPU) they are used instead either way."""
        if compile_step is not None and not isinstance(compile_step, bool):
            raise ValueError(f"compile_step must be True, False or None, got {compile_step!r}")
        if config.num_inputs != 2 or config.num_outputs != 1:
            raise ValueError("the non-Markov spiking controller needs num_inputs=2 and num_outputs=1, got "
                             f"{config.num_inputs} and {config.num_outputs}")
        self.cfg, self.spec, self.plant = config, spec, plant
        N = genomes.num_nodes
        # Simulate only node slots some genome uses: the index is sized for the largest genome.
        self.nodes = torch.nonzero(genomes.node.reshape(-1, N).any(0)).flatten()
        w = genomes.effective_weight().reshape(-1, N, N)[:, self.nodes][:, :, self.nodes]
        N = len(self.nodes)
        out = int(torch.nonzero(self.nodes == config.first_output).flatten()[0])
        self.w_out = w[:, :, out]  # decoder weights into the output node, [B, N]
        self.w = w * (spec.synapse_kick_mv / spec.dt_ms)  # synaptic current per spike (mV/ms)
        self.sigma = genomes.sigma.reshape(-1)
        self.substeps = int(round(tau_s * 1000.0 / spec.dt_ms))
        if abs(self.substeps * spec.dt_ms - tau_s * 1000.0) > 1e-9:
            raise ValueError(f"tau ({tau_s * 1000} ms) must be a whole number of dt_ms ({spec.dt_ms} ms)")
        B = w.shape[0]
        self.state = recurrent_init((B, N), spec.neuron, device=w.device, dtype=w.dtype)
        self.history = torch.zeros(spec.rate_window_steps, B, N, dtype=w.dtype, device=w.device)
        self.step_index = 0
        self.window_s = tau_s
        # The fused C kernel repeats the torch step's arithmetic bit for bit (tested); torch otherwise.
        self.fused = use_fused and fused_supports(self.state, self.w, spec.neuron)
        self.tau_s = tau_s
        self.loop_fused = (self.fused and spec.rate_window_steps <= MAX_WINDOW and loop_available()
                           and plant_state_ok(w))
        # The torch path's substep (where the C kernels do not run): compiled, or the reference.
        wants_compile = w.device.type == "cuda" if compile_step is None else compile_step
        self.network_step = (CompiledSubstep(spec.neuron, dt_ms=spec.dt_ms) if wants_compile
                             else functools.partial(eager_substep, p=spec.neuron, dt_ms=spec.dt_ms))

    def run_fused(self, state0: Tensor, max_steps: int) -> Tensor | None:
        """Steps balanced per row from ``state0``, by the closed-loop C kernel; None if unavailable."""
        if not self.loop_fused or self.step_index:
            return None
        spec = self.spec
        return spiking_loop(self.w, self.w_out, self.sigma, state0, max_steps=max_steps, substeps=self.substeps,
                            window=spec.rate_window_steps, dt_ms=spec.dt_ms, neuron=spec.neuron,
                            i_background=spec.i_background, i_input_max=spec.i_input_max, window_s=self.window_s,
                            tau_s=self.tau_s, plant=self.plant)

    def keep(self, rows: Tensor) -> None:
        self.w, self.w_out, self.sigma = self.w[rows], self.w_out[rows], self.sigma[rows]
        self.state = type(self.state)(*(t[rows] for t in self.state))
        self.history = self.history[:, rows]

    def act(self, plant_state: Tensor) -> tuple[Tensor, Tensor]:
        """Force (N) for each batch row, and the spike counts of this control step."""
        cfg, spec = self.cfg, self.spec
        i_ext = torch.full_like(self.state.v, spec.i_background)
        i_ext[:, : cfg.num_inputs] += spec.i_input_max * normalized_inputs(plant_state, self.plant).to(i_ext.dtype)
        if self.fused:
            counts, self.state = fused_recurrent_izhikevich_steps(i_ext, self.state, self.w, spec.neuron,
                                                                  dt_ms=spec.dt_ms, substeps=self.substeps)
        else:
            counts, state = torch.zeros_like(i_ext), self.state
            for _ in range(self.substeps):
                state, counts = self.network_step(i_ext, state, self.w, counts)
            self.state = state
        self.history[self.step_index % spec.rate_window_steps] = counts
        self.step_index += 1
        steps_in_window = min(self.step_index, spec.rate_window_steps)
        rates = self.history.sum(0) / (steps_in_window * self.window_s)  # Hz
        # A sequential sum (cumsum): node slots another genome of the batch uses add exact
        # zeros here, so a genome's force does not depend on the batch it is evaluated in.
        drive = torch.cumsum(rates * self.w_out, -1)[:, -1]
        force = 10.0 * (2.0 * _sigmoid(self.sigma * drive) - 1.0)
        return force, counts


class SigmoidPolicy:
    """Sigmoid NEAT: a batched recurrent sigmoid network.

    Non-Markov task (default): inputs x and theta, ``F = 10 (2 y - 1)``. Markov task:
    ``observe=MARKOV_OBSERVE, limits=markov_limits(plant), bang_bang=True``: all four state
    variables, ``F = +10 N`` if ``y > 0.5`` else ``-10 N`` (NEAT's pole-balancing output).
    """

    def __init__(self, genomes: Genomes, config: NEATConfig, spec: SigmoidSpec, plant: CartPoleParams,
                 *, tau_s: float = 0.01, use_fused: bool = True, observe: tuple[int, ...] = (X, THETA),
                 limits: tuple[float, ...] | None = None, bang_bang: bool = False) -> None:
        if config.num_inputs != len(observe) or config.num_outputs != 1:
            raise ValueError(f"this sigmoid controller needs num_inputs={len(observe)} and num_outputs=1, got "
                             f"{config.num_inputs} and {config.num_outputs}")
        self.cfg, self.spec, self.plant, self.tau_s = config, spec, plant, tau_s
        self.observe, self.bang_bang = tuple(observe), bang_bang
        self.limits = (plant.x_limit, plant.theta_limit) if limits is None else tuple(limits)
        N = genomes.num_nodes
        self.w = genomes.effective_weight().reshape(-1, N, N)
        self.values = torch.zeros(self.w.shape[0], N, dtype=self.w.dtype, device=self.w.device)
        self.loop_fused = use_fused and plant_state_ok(self.w) and N <= MAX_NODES and loop_available()
        self.stepped = False

    def run_fused(self, state0: Tensor, max_steps: int) -> Tensor | None:
        """Steps balanced per row from ``state0``, by the closed-loop C kernel; None if unavailable."""
        if not self.loop_fused or self.stepped:
            return None
        cfg = self.cfg
        return sigmoid_loop(self.w, state0, num_inputs=cfg.num_inputs, first_output=cfg.first_output,
                            max_steps=max_steps, updates=self.spec.updates_per_step, slope=NEAT_SIGMOID_SLOPE,
                            tau_s=self.tau_s, plant=self.plant, observe=self.observe, limits=self.limits,
                            bang_bang=self.bang_bang)

    def keep(self, rows: Tensor) -> None:
        self.w, self.values = self.w[rows], self.values[rows]

    def act(self, plant_state: Tensor) -> tuple[Tensor, Tensor]:
        cfg = self.cfg
        self.stepped = True
        inputs = normalized_inputs(plant_state, self.plant, self.observe, self.limits).to(self.w.dtype)
        y = self.values
        for _ in range(self.spec.updates_per_step):
            y = y.clone()
            y[:, : cfg.num_inputs] = inputs
            y[:, cfg.num_inputs : cfg.first_output] = 1.0
            y = _sigmoid(NEAT_SIGMOID_SLOPE * (y.unsqueeze(1) @ self.w).squeeze(1))
            y[:, : cfg.num_inputs] = inputs
            y[:, cfg.num_inputs : cfg.first_output] = 1.0
        self.values = y
        out = y[:, cfg.first_output]
        if self.bang_bang:
            return torch.where(out > 0.5, 10.0, -10.0).to(out.dtype), y
        return 10.0 * (2.0 * out - 1.0), y


# Markov task (Table I): all four state variables. The paper gives no bounds for the
# velocities; these cover what a balancing cart-pole reaches (values beyond are clamped).
MARKOV_OBSERVE = (X, X_DOT, THETA, THETA_DOT)
X_DOT_LIMIT = 1.5  # m/s
THETA_DOT_LIMIT = 2.0  # rad/s


def markov_limits(plant: CartPoleParams) -> tuple[float, float, float, float]:
    """Normalisation bounds of (x, x_dot, theta, theta_dot): failure limits and the velocity bounds."""
    return (plant.x_limit, X_DOT_LIMIT, plant.theta_limit, THETA_DOT_LIMIT)


@dataclass(frozen=True)
class MarkovSpikingSpec:
    """The Markov spiking controller's free choices (the paper gives none of these values)."""

    neuron: IzhikevichParams = QIU2019
    dt_ms: float = 0.5  # as SpikingSpec
    i_background: float = 30.0  # mV/ms (nA), as SpikingSpec: ~270 Hz alone
    # [Qiu19] "the normalized input variables are encoded as a probability to generate a spike"
    # at each time step: here each 0.5 ms substep, at up to 1000 Hz (probability 0.5 at input 1).
    input_rate_max_hz: float = 1000.0
    synapse_kick_mv: float = 1.0  # as SpikingSpec
    rate_window_steps: int = 1  # rates over the last control step (20 ms)
    # "weighted_rate": the output node decodes as in the non-Markov task (Fig. 5's caption), from
    # the rates r_j of the nodes wired to it, each taken relative to its rate at rest (inputs: at
    # the centre of their range; neurons: under the background current alone):
    # F = +10 N when sum_j w_j (r_j - rest_j) > threshold_hz (default 0), else -10 N.
    # "output_neuron": F = +10 N when the output neuron's own rate exceeds threshold_hz (default:
    # its rate under the background current alone, background_rate_hz).
    decoder: str = "weighted_rate"
    threshold_hz: float | None = None

    def __post_init__(self) -> None:
        check_dt(self.dt_ms)
        for name in ("i_background", "input_rate_max_hz", "synapse_kick_mv", "threshold_hz"):
            value = getattr(self, name)
            if value is None:
                continue
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"MarkovSpikingSpec.{name} must be finite and >= 0, got {value!r}")
        if not 1 <= self.rate_window_steps <= MAX_WINDOW:
            raise ValueError(f"MarkovSpikingSpec.rate_window_steps must be in 1..{MAX_WINDOW}, "
                             f"got {self.rate_window_steps}")
        if self.decoder not in ("weighted_rate", "output_neuron"):
            raise ValueError(f"MarkovSpikingSpec.decoder must be 'weighted_rate' or 'output_neuron', got {self.decoder!r}")
        if self.input_rate_max_hz * self.dt_ms / 1000.0 > 1.0 + 1e-12:
            raise ValueError("MarkovSpikingSpec.input_rate_max_hz * dt_ms must be at most one spike per substep")


@functools.lru_cache(maxsize=32)
def background_rate_hz(neuron: IzhikevichParams, current: float, dt_ms: float) -> float:
    """Steady firing rate (Hz) of one neuron under a constant ``current`` (mV/ms): spikes in
    2 s after 1 s of settling, integrated as the networks are (Heun, sub-step reset)."""
    steps = int(round(3000.0 / dt_ms))
    v, u = izhikevich_init((1,), neuron, dtype=torch.float64)
    z, _ = izhikevich_run(torch.full((steps, 1), float(current), dtype=torch.float64),
                          IzhikevichState(v, u), neuron, dt_ms=dt_ms)
    return float(z[steps // 3:].sum()) / 2.0


class MarkovSpikingPolicy:
    """NEAT-SNN for the Markov task: Bernoulli-coded input spikes, bang-bang output.

    Input nodes 0..3 are spike sources, not neurons: in every substep input k fires with
    probability ``norm_k * input_rate_max_hz * dt``, from a counter-based random stream keyed
    by a hash of the genome (``tasks.counter_rng``: a genome's episode is the same in any
    batch). Whole episodes run in the closed-loop C kernel on CPU (``run_fused``); ``act`` is
    the readable torch reference, one control step of the whole batch (any device; used to
    record episodes), and draws the same spikes.

    ``noise_seed`` (0: the stream evolution saw) re-keys every genome's input noise, to test
    a champion on spike trains it was not selected on.
    """

    def __init__(self, genomes: Genomes, config: NEATConfig, spec: MarkovSpikingSpec, tau_s: float,
                 plant: CartPoleParams, *, use_fused: bool = True, noise_seed: int = 0) -> None:
        if config.num_inputs != 4 or config.num_outputs != 1:
            raise ValueError("the Markov spiking controller needs num_inputs=4 and num_outputs=1, got "
                             f"{config.num_inputs} and {config.num_outputs}")
        w = genomes.effective_weight()
        self.cfg, self.spec, self.plant, self.tau_s = config, spec, plant, tau_s
        self.loop_fused = use_fused and plant_state_ok(w) and loop_available()
        N = genomes.num_nodes
        flat = w.reshape(-1, N, N)
        # Before compaction: the same genome, the same key, in any batch.
        self.keys = genome_keys(flat) if self.loop_fused else fnv1a_keys(flat)
        if noise_seed:
            self.keys = self.keys ^ mix64(torch.tensor(int(noise_seed), dtype=torch.int64))
        self.nodes = torch.nonzero(genomes.node.reshape(-1, N).any(0)).flatten()
        self.w = flat[:, self.nodes][:, :, self.nodes] * (spec.synapse_kick_mv / spec.dt_ms)
        self.out = int(torch.nonzero(self.nodes == config.first_output).flatten()[0])
        self.w_out = self.rest_hz = None
        bg_hz = background_rate_hz(spec.neuron, spec.i_background, spec.dt_ms)
        if spec.decoder == "weighted_rate":
            self.w_out = flat[:, self.nodes][:, :, self.out]
            rest = torch.full((len(self.nodes),), bg_hz, dtype=torch.float64)
            rest[self.nodes.cpu() < config.num_inputs] = 0.5 * spec.input_rate_max_hz
            self.rest_hz = rest
        if spec.threshold_hz is not None:
            self.threshold_hz = spec.threshold_hz
        elif spec.decoder == "weighted_rate":
            self.threshold_hz = 0.0
        else:
            self.threshold_hz = bg_hz
        self.substeps = int(round(tau_s * 1000.0 / spec.dt_ms))
        if abs(self.substeps * spec.dt_ms - tau_s * 1000.0) > 1e-9:
            raise ValueError(f"tau ({tau_s * 1000} ms) must be a whole number of dt_ms ({spec.dt_ms} ms)")
        B, n = self.w.shape[0], len(self.nodes)
        self.state = recurrent_init((B, n), spec.neuron, device=w.device, dtype=w.dtype)
        self.history = torch.zeros(spec.rate_window_steps, B, n, dtype=w.dtype, device=w.device)
        self.step_index = 0

    def run_fused(self, state0: Tensor, max_steps: int) -> Tensor | None:
        """Steps balanced per row from ``state0``, by the closed-loop C kernel; None if unavailable."""
        if not self.loop_fused or self.step_index:
            return None
        spec = self.spec
        return markov_spiking_loop(
            self.w, self.w_out, self.rest_hz, self.keys, state0, num_inputs=self.cfg.num_inputs, output=self.out,
            max_steps=max_steps, substeps=self.substeps, window=spec.rate_window_steps, dt_ms=spec.dt_ms,
            neuron=spec.neuron, i_background=spec.i_background,
            spike_prob_max=spec.input_rate_max_hz * spec.dt_ms / 1000.0, threshold_hz=self.threshold_hz,
            window_s=self.tau_s, tau_s=self.tau_s, plant=self.plant, observe=MARKOV_OBSERVE,
            limits=markov_limits(self.plant))

    def keep(self, rows: Tensor) -> None:
        self.w, self.keys = self.w[rows], self.keys[rows]
        if self.w_out is not None:
            self.w_out = self.w_out[rows]
        self.state = type(self.state)(*(t[rows] for t in self.state))
        self.history = self.history[:, rows]

    def act(self, plant_state: Tensor) -> tuple[Tensor, Tensor]:
        """Force (N) for each batch row, and the spike counts of this control step (inputs
        included). The same arithmetic, in the same order, as the C kernel."""
        spec, n_in = self.spec, self.cfg.num_inputs
        dtype = self.w.dtype
        p_max = torch.tensor(spec.input_rate_max_hz * spec.dt_ms / 1000.0, dtype=dtype)
        prob = (normalized_inputs(plant_state.to(dtype), self.plant, MARKOV_OBSERVE, markov_limits(self.plant))
                * p_max).to(torch.float64)
        i_ext = torch.full_like(self.state.v, spec.i_background)
        counts = torch.zeros_like(self.state.v)
        keys = self.keys.to(self.w.device).unsqueeze(1)
        # Draw k of substep q of control step t is counter (t * substeps + q) * n_in + k.
        counters = torch.arange(self.substeps * n_in, device=self.w.device).view(self.substeps, 1, n_in)
        counters = counters + self.step_index * self.substeps * n_in
        state = self.state
        for q in range(self.substeps):
            z_in = (uniform01(keys, counters[q]) < prob).to(dtype)
            z = torch.cat([z_in, state.z[:, n_in:]], dim=1)  # the inputs' spikes of this substep
            z_new, state = recurrent_izhikevich_step(i_ext, state._replace(z=z), self.w, spec.neuron,
                                                     dt_ms=spec.dt_ms, validate=False)
            counts = counts + torch.cat([z_in, z_new[:, n_in:]], dim=1)
        self.state = state
        window = spec.rate_window_steps
        self.history[self.step_index % window] = counts
        self.step_index += 1
        total = self.history[0]
        for k in range(1, window):  # slot order, as the kernel sums
            total = total + self.history[k]
        denom = torch.tensor(min(self.step_index, window) * self.tau_s, dtype=dtype)
        rates = total / denom  # Hz
        if self.w_out is not None:
            terms = (rates - self.rest_hz.to(rates)) * self.w_out
            drive = torch.cumsum(terms.to(torch.float64), -1)[:, -1].to(dtype)
        else:
            drive = rates[:, self.out]
        force = torch.where(drive > self.threshold_hz, 10.0, -10.0).to(dtype)
        return force, counts


def plant_state_ok(w: Tensor) -> bool:
    """The closed-loop C kernels run CPU float32/float64 batches."""
    return w.device.type == "cpu" and w.dtype in (torch.float32, torch.float64)


def closed_loop(policy, state0: Tensor, *, tau_s: float, max_steps: int, plant: CartPoleParams = DEFAULT_PLANT,
                record: bool = False, compact_below: float = 0.5) -> tuple[Tensor, dict | None]:
    """Run every batch row until it fails or reaches ``max_steps``; returns steps survived ``[B]``.

    Rows that failed stop costing compute: when fewer than ``compact_below`` of the rows
    still running are alive, the batch is compacted (policy state included). With
    ``record``, returns x, theta, F and spike counts per step (for plots; no compaction).
    On CPU, a policy with a closed-loop C kernel (``run_fused``) runs there instead, one
    thread per row, and returns the same steps to rounding (``tests/tasks/test_fused_loop.py``).
    """
    if not record:
        fused = getattr(policy, "run_fused", lambda *_: None)(state0, max_steps)
        if fused is not None:
            return fused.to(state0.device), None
    B = state0.shape[0]
    device = state0.device
    steps = torch.zeros(B, dtype=torch.long, device=device)
    rows = torch.arange(B, device=device)  # original index of each running row
    state = state0.clone()
    alive = torch.ones(B, dtype=torch.bool, device=device)
    trace: dict | None = {"x": [], "theta": [], "force": [], "activity": []} if record else None
    for _ in range(max_steps):
        force, activity = policy.act(state)
        moved = cartpole_step(state, force.to(state.dtype), tau_s, plant)
        # Failed rows keep their last state: a fallen pole is not simulated further.
        state = torch.where(alive.unsqueeze(-1), moved, state)
        check_state(state, "cart-pole state after a control step")
        alive = alive & ~cartpole_failed(state, plant)
        steps[rows] += alive.long()
        if trace is not None:
            trace["x"].append(state[:, X].clone())
            trace["theta"].append(state[:, THETA].clone())
            trace["force"].append(force.clone())
            trace["activity"].append(activity.clone())
            if not bool(alive.any()):
                break
            continue
        n_alive = int(alive.sum())
        if n_alive == 0:
            break
        if n_alive < compact_below * alive.numel():
            keep = torch.nonzero(alive).squeeze(1)
            policy.keep(keep)
            rows, state, alive = rows[keep], state[keep], alive[keep]
    if trace is not None:
        trace = {k: torch.stack(v) for k, v in trace.items()}
    return steps, trace
