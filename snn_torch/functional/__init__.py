"""Pure tensor functions: the numerics of snn_torch (state in, state out, no globals)."""

from snn_torch.functional.decode import bang_bang_force, firing_rate, weighted_rate_force
from snn_torch.functional.encode import (
    background_current,
    bernoulli_encode,
    current_encode,
    normalize,
    rate_encode,
)
from snn_torch.functional.izhikevich import (
    CHATTERING,
    DEFAULT_DT_MS,
    FAST_SPIKING,
    INTRINSICALLY_BURSTING,
    LOW_THRESHOLD_SPIKING,
    PRESETS,
    QIU2019,
    QIU2019_FIG1,
    REGULAR_SPIKING,
    RESONATOR,
    SOLVERS,
    IzhikevichParams,
    IzhikevichState,
    izhikevich_init,
    izhikevich_run,
    izhikevich_step,
)
from snn_torch.functional.izhikevich_fused import izhikevich_step_fused
from snn_torch.functional.latency import latency_encode
from snn_torch.functional.lif import (
    LIFParams,
    LIFRecurrentState,
    LIFState,
    LIParams,
    LIState,
    li_init,
    li_step,
    lif_init,
    lif_step,
)
from snn_torch.functional.recurrent import (
    RecurrentState,
    SynapticState,
    masked_weights,
    recurrent_init,
    recurrent_izhikevich_run,
    recurrent_izhikevich_step,
    synaptic_decay,
)
from snn_torch.functional.threshold import fast_sigmoid, heaviside, superspike, triangle

__all__ = [
    "CHATTERING", "DEFAULT_DT_MS", "FAST_SPIKING", "INTRINSICALLY_BURSTING",
    "LOW_THRESHOLD_SPIKING", "PRESETS", "QIU2019", "QIU2019_FIG1", "REGULAR_SPIKING",
    "RESONATOR", "SOLVERS", "IzhikevichParams", "IzhikevichState", "RecurrentState", "SynapticState",
    "bang_bang_force", "background_current", "bernoulli_encode", "current_encode",
    "fast_sigmoid", "firing_rate", "heaviside", "izhikevich_init", "izhikevich_run",
    "izhikevich_step", "izhikevich_step_fused", "masked_weights", "normalize", "rate_encode", "recurrent_init",
    "recurrent_izhikevich_run", "recurrent_izhikevich_step", "superspike", "synaptic_decay", "triangle",
    "weighted_rate_force", "LIFParams", "LIFRecurrentState", "LIFState", "LIParams", "LIState", "latency_encode",
    "li_init", "li_step", "lif_init", "lif_step",
]
