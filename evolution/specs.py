"""Controller specs: a spiking or sigmoid controller's physics and coding choices, in one place.

``SpikingSpec`` (NEAT-SNN) and ``SigmoidSpec`` (sigmoid NEAT) are frozen dataclasses, checked on
construction; the encoder and decoder tables name the ``snn_torch.modules.coding`` modules they
pick. ``evolution.phenotype`` builds the controllers from them; ``evolution.defaults`` derives
the specs a task gets by default.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from evolution.input_coding import check_coding
from snn_torch.functional.izhikevich import QIU2019, IzhikevichParams, check_dt, check_params
from snn_torch.functional.recurrent import synaptic_decay
from snn_torch.modules.coding import (
    BangBang,
    BernoulliEncoder,
    CurrentEncoder,
    LinearReadout,
    SigmoidForce,
    UnitForce,
)

__all__ = ["SpikingSpec", "SigmoidSpec", "NEAT_SIGMOID_SLOPE", "ENCODERS", "SPIKING_DECODERS", "SIGMOID_DECODERS",
           "DECODER_CODES"]

NEAT_SIGMOID_SLOPE = 4.9  # [NEAT02]
# The spiking controller's encoders, name -> module from (spec, substeps per control step).
ENCODERS = {
    "current": lambda spec, substeps: CurrentEncoder(spec.i_input_max),
    "bernoulli": lambda spec, substeps: BernoulliEncoder(spec.input_rate_max_hz, dt_ms=spec.dt_ms, substeps=substeps),
}
# Each controller's decoders, name -> module from (action_max, spec). The spiking ones read the
# drive ``d`` with the genome's gain sigma: ``sigmoid_force`` inside the sigmoid, ``linear`` as a
# factor, ``bang_bang`` not at all (one threshold rule for both controllers: ``BangBang``, strict >).
SPIKING_DECODERS = {
    "sigmoid_force": lambda a_max, spec: SigmoidForce(a_max),
    "bang_bang": lambda a_max, spec: BangBang(a_max, spec.threshold),
    "linear": lambda a_max, spec: LinearReadout(a_max, low=-a_max, high=a_max),
}
SIGMOID_DECODERS = {
    "sigmoid_force": lambda a_max, spec: UnitForce(a_max),
    "bang_bang": lambda a_max, spec: BangBang(a_max, threshold=0.5),
}
DECODER_CODES = {"sigmoid_force": 0, "bang_bang": 1, "linear": 2}  # the C decoders' (recurrent_izhikevich.h, episodes.h)
SPIKING_STARTS = ("rest", "spread")  # SpikingSpec.start


@dataclass(frozen=True, repr=False)
class SpikingSpec:
    """A spiking controller's physics and coding, in one place. Defaults: the choices made for
    Qiu et al.'s non-Markov cart-pole (the paper gives none of these values).

    Attributes:
        neuron: Izhikevich parameters of every node ([Qiu19] Fig. 2's neuron).
        dt_ms: substep (ms); snn_torch's validated default: rates within 3 Hz + 5 % of a fine
            reference. A control step is ``task.control_period_s / dt`` substeps.
        network_ms: network time per control step (ms), a whole number of ``dt_ms``; None
            (default): the task's control period. Shorter than the period, the network reacts
            faster (its rate window is shorter) and costs fewer substeps; the plant still
            advances its own period per step.
        i_background: current into every neuron (mV/ms, the paper's nA). Alone a neuron then
            fires at ~270 Hz, high on Fig. 2's f-I curve, so inhibitory input lowers its rate
            instead of silencing it ([Qiu19]'s "frequency sufficiency"). The choice that mattered
            most: tuning seeds 5000-5031 solved every run for 20 to 60 nA, 5/16 at 5 nA, none at 0.
        synapse_kick_mv: mV jump of the postsynaptic membrane per presynaptic spike per unit
            weight (a current of ``w * kick / dt_ms`` for one substep, so it does not depend on
            dt; Izhikevich 2003's networks add ``w`` for one 1 ms step).
        synapse_tau_ms: time constant (ms) of exponential (current-based) synapses: a spike's
            charge, the same as above, arrives spread over about ``tau``, so a neuron also sees
            a lagged copy of its input (memory across control steps). 0 (default): it arrives in
            one substep. Above 0 the C kernels run it too; the compiled (CUDA) step does not.
        encoder: ``"current"``: input node ``k`` gets ``i_input_max * x_k`` (mV/ms) on top of the
            background; ``"bernoulli"``: input nodes are spike sources firing with probability
            ``x_k * input_rate_max_hz * dt`` per substep, keyed by a hash of the genome.
        i_input_max: mV/ms at normalised input 1 (~270 -> ~700 Hz with the background); also
            the current into bias nodes.
        input_rate_max_hz: the Bernoulli encoder's rate at input 1 ([Qiu19]'s Markov task: the
            normalised value is the spike probability per step: 1000 Hz at 0.5 ms is p = 0.5).
        decoder: from the rates ``r_j`` of the nodes wired to output ``k`` with weights ``w_jk``,
            the drive ``d_k = sum_j w_jk (r_j - rest_j)`` (Hz x weight; ``rest_j`` = 0 unless
            ``rest_relative``). ``"sigmoid_force"``: ``a = a_max (2 sigmoid(sigma d) - 1)``
            ([Qiu19] eq. 10); ``"bang_bang"``: ``a = +-a_max`` on ``d > threshold``;
            ``"linear"``: ``a = clamp(sigma d, -1, 1) a_max``. ``sigma``: the genome's evolved gain.
        rate_window_steps: control steps in the firing-rate window.
        rest_relative: rates relative to each node's rate at rest (inputs: at the middle of
            their range; neurons: under the background current alone, ``rest_rate_hz``).
        threshold: the bang-bang decoder's threshold on the drive.
        input_coding: how observations become inputs (``evolution.input_coding``): ``"unit"``
            ([0, 1] over the task's bounds, the paper's), ``"signed"`` ([-1, 1] about the
            middle: a current below the background's under the middle; not with the Bernoulli
            encoder) or ``"push_pull"`` (two input nodes per variable, the positive and the
            negative part of the signed value); ``clip_inputs``: clip the signed value to [-1, 1].
        start: each episode's first network state. ``"rest"`` (the paper's): every neuron at
            ``v0`` (-65 mV), so all fire their first spikes together and, through strong
            synapses, jolt the first control steps' actions. ``"spread"``: each neuron at a point
            of its firing cycle under the background current alone, the point set by its node
            slot (the same in any batch), so the network starts as it runs.
    """

    neuron: IzhikevichParams = QIU2019
    dt_ms: float = 0.5
    network_ms: float | None = None
    i_background: float = 30.0
    synapse_kick_mv: float = 1.0
    synapse_tau_ms: float = 0.0
    encoder: str = "current"
    i_input_max: float = 60.0
    input_rate_max_hz: float = 1000.0
    decoder: str = "sigmoid_force"
    rate_window_steps: int = 4
    rest_relative: bool = False
    threshold: float = 0.0
    input_coding: str = "unit"
    clip_inputs: bool = True
    start: str = "rest"

    def __post_init__(self) -> None:
        check_coding("SpikingSpec", self.input_coding, self.clip_inputs)
        if self.start not in SPIKING_STARTS:
            raise ValueError(f"SpikingSpec.start must be one of {SPIKING_STARTS}, got {self.start!r}")
        if self.encoder == "bernoulli" and self.input_coding == "signed":
            raise ValueError("SpikingSpec.input_coding='signed' cannot drive the Bernoulli encoder (a spike "
                             "probability is not negative): use 'push_pull'")
        check_dt(self.dt_ms)
        if self.network_ms is not None:
            if isinstance(self.network_ms, bool) or not isinstance(self.network_ms, (int, float)) \
                    or not math.isfinite(self.network_ms) or self.network_ms <= 0:
                raise ValueError(f"SpikingSpec.network_ms must be a positive number of ms or None, got "
                                 f"{self.network_ms!r}")
            self.substeps(self.network_ms / 1000.0)
        check_params(self.neuron)
        try:
            synaptic_decay(self.synapse_tau_ms, self.dt_ms)
        except ValueError as exc:
            raise ValueError(f"SpikingSpec.{exc}") from None
        for name in ("i_background", "i_input_max", "input_rate_max_hz", "synapse_kick_mv", "threshold"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"SpikingSpec.{name} must be a finite number, got {value!r}")
        if self.input_rate_max_hz < 0:
            raise ValueError(f"SpikingSpec.input_rate_max_hz must be >= 0, got {self.input_rate_max_hz!r}")
        if self.encoder not in ENCODERS:
            raise ValueError(f"SpikingSpec.encoder must be one of {tuple(ENCODERS)}, got {self.encoder!r}")
        if self.decoder not in SPIKING_DECODERS:
            raise ValueError(f"SpikingSpec.decoder must be one of {tuple(SPIKING_DECODERS)}, got {self.decoder!r}")
        if isinstance(self.rate_window_steps, bool) or not isinstance(self.rate_window_steps, int) \
                or self.rate_window_steps < 1:
            raise ValueError(f"SpikingSpec.rate_window_steps must be an int >= 1, got {self.rate_window_steps!r}")
        if self.encoder == "bernoulli" and self.input_rate_max_hz * self.dt_ms / 1000.0 > 1.0 + 1e-12:
            raise ValueError("SpikingSpec.input_rate_max_hz * dt_ms must be at most one spike per substep")

    def period_s(self, task_period_s: float) -> float:
        """Network time per control step (s) on a task whose control period is ``task_period_s``."""
        return task_period_s if self.network_ms is None else self.network_ms / 1000.0

    def __repr__(self) -> str:
        # ``start`` only where it is not the default, so a spec's repr (a checkpoint's identity
        # of `snn-neat evolve`) reads as it did before the field existed
        shown = [f for f in dataclasses.fields(self) if f.name != "start" or self.start != "rest"]
        return f"SpikingSpec({', '.join(f'{f.name}={getattr(self, f.name)!r}' for f in shown)})"

    def substeps(self, period_s: float) -> int:
        """Substeps of ``dt_ms`` in a control period of ``period_s`` seconds (a whole number)."""
        substeps = int(round(period_s * 1000.0 / self.dt_ms))
        if substeps < 1 or abs(substeps * self.dt_ms - period_s * 1000.0) > 1e-9:
            raise ValueError(f"the control period ({period_s * 1000} ms) must be a whole number of dt_ms "
                             f"({self.dt_ms} ms)")
        return substeps


@dataclass(frozen=True)
class SigmoidSpec:
    """A sigmoid controller's choices: ``updates_per_step`` network updates per control step
    (NEAT pole balancing: 1) and the decoder of the outputs ``y`` in (0, 1):
    ``"sigmoid_force"``: ``a = a_max (2 y - 1)``; ``"bang_bang"``: ``a = +-a_max`` on ``y > 0.5``.
    ``input_coding`` and ``clip_inputs``: the input nodes' values (``evolution.input_coding``:
    ``"unit"`` [0, 1], ``"signed"`` [-1, 1], ``"push_pull"`` two nodes per variable)."""

    updates_per_step: int = 1
    decoder: str = "sigmoid_force"
    slope: float = NEAT_SIGMOID_SLOPE
    input_coding: str = "unit"
    clip_inputs: bool = True

    def __post_init__(self) -> None:
        check_coding("SigmoidSpec", self.input_coding, self.clip_inputs)
        if isinstance(self.updates_per_step, bool) or not isinstance(self.updates_per_step, int) \
                or self.updates_per_step < 1:
            raise ValueError(f"SigmoidSpec.updates_per_step must be an int >= 1, got {self.updates_per_step!r}")
        if self.decoder not in SIGMOID_DECODERS:
            raise ValueError(f"SigmoidSpec.decoder must be one of {tuple(SIGMOID_DECODERS)}, got {self.decoder!r}")
