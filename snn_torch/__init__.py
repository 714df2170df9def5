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
    RecurrentState,
    fast_sigmoid,
    heaviside,
    superspike,
)
from snn_torch.modules import Izhikevich, IzhikevichCell, PopulationRecurrentIzhikevich  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "CHATTERING", "FAST_SPIKING", "PRESETS", "QIU2019", "QIU2019_FIG1", "REGULAR_SPIKING",
    "Izhikevich", "IzhikevichCell", "IzhikevichParams", "IzhikevichState",
    "PopulationRecurrentIzhikevich", "RecurrentState", "fast_sigmoid", "functional",
    "heaviside", "superspike", "__version__",
]
