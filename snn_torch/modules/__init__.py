"""Thin ``nn.Module`` shells over ``snn_torch.functional`` (explicit state in, state out)."""

from snn_torch.modules.encoders import ConstantCurrentEncoder, LatencyEncoder, RateEncoder
from snn_torch.modules.izhikevich import Izhikevich, IzhikevichCell
from snn_torch.modules.lif import LI, LIF, LICell, LIFCell
from snn_torch.modules.nir_io import export_nir, import_nir
from snn_torch.modules.recurrent import PopulationRecurrentIzhikevich
from snn_torch.modules.recurrent_layers import IzhikevichRecurrent, LIFRecurrent
from snn_torch.modules.stateful import Stateful, detach_states, reset_states

__all__ = [
    "ConstantCurrentEncoder", "Izhikevich", "IzhikevichCell", "IzhikevichRecurrent", "LatencyEncoder", "LI",
    "LICell", "LIF", "LIFCell", "LIFRecurrent", "PopulationRecurrentIzhikevich", "RateEncoder", "Stateful",
    "detach_states", "export_nir", "import_nir", "reset_states",
]
