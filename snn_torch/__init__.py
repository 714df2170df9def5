"""snn_torch: Izhikevich spiking neurons as torch functions and modules.

Units throughout: time in ms, membrane potential in mV, rates in Hz, currents in the
Izhikevich model's units (mV/ms; Qiu et al. write nA).
"""

from snn_torch import functional
from snn_torch.functional import (
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
from snn_torch.modules import Izhikevich, IzhikevichCell, PopulationRecurrentIzhikevich

__version__ = "0.1.0"

__all__ = [
    "CHATTERING", "FAST_SPIKING", "PRESETS", "QIU2019", "QIU2019_FIG1", "REGULAR_SPIKING",
    "Izhikevich", "IzhikevichCell", "IzhikevichParams", "IzhikevichState",
    "PopulationRecurrentIzhikevich", "RecurrentState", "fast_sigmoid", "functional",
    "heaviside", "superspike", "__version__",
]
