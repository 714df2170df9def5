"""snn_torch: Izhikevich spiking neurons as torch functions and modules.

Units throughout: time in ms, membrane potential in mV, rates in Hz, currents in the
Izhikevich model's units (mV/ms; Qiu et al. write nA).
"""

from snn_torch._vml_warmup import warm_up_vml

warm_up_vml()  # before any parallel float op: see snn_torch/_vml_warmup.py (an MKL first-call race)

from snn_torch import functional  # noqa: E402
from snn_torch.functional import (  # noqa: E402
    CHATTERING,
    FAST_SPIKING,
    PRESETS,
    QIU2019,
    QIU2019_FIG1,
    REGULAR_SPIKING,
    IzhikevichParams,
    IzhikevichState,
    LIFParams,
    LIFRecurrentState,
    LIFState,
    LIParams,
    LIState,
    RecurrentState,
    fast_sigmoid,
    heaviside,
    superspike,
)
from snn_torch.modules import (  # noqa: E402
    LI,
    LIF,
    ConstantCurrentEncoder,
    Izhikevich,
    IzhikevichCell,
    IzhikevichRecurrent,
    LatencyEncoder,
    LICell,
    LIFCell,
    LIFRecurrent,
    PopulationRecurrentIzhikevich,
    RateEncoder,
    Stateful,
    detach_states,
    export_nir,
    import_nir,
    reset_states,
)

__version__ = "0.1.0"

__all__ = [
    "CHATTERING", "FAST_SPIKING", "PRESETS", "QIU2019", "QIU2019_FIG1", "REGULAR_SPIKING",
    "Izhikevich", "IzhikevichCell", "IzhikevichParams", "IzhikevichState",
    "PopulationRecurrentIzhikevich", "RecurrentState", "fast_sigmoid", "functional",
    "heaviside", "superspike", "__version__",
    "ConstantCurrentEncoder", "IzhikevichRecurrent", "LatencyEncoder", "LI", "LICell", "LIF", "LIFCell",
    "LIFParams", "LIFRecurrent", "LIFRecurrentState", "LIFState", "LIParams", "LIState", "RateEncoder", "Stateful",
    "detach_states", "export_nir", "import_nir", "reset_states",
]
