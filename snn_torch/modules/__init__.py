"""Thin ``nn.Module`` shells over ``snn_torch.functional`` (explicit state in, state out)."""

from snn_torch.modules.izhikevich import Izhikevich, IzhikevichCell
from snn_torch.modules.recurrent import PopulationRecurrentIzhikevich

__all__ = ["Izhikevich", "IzhikevichCell", "PopulationRecurrentIzhikevich"]
