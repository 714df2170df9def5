"""The C kernel of ``PopulationRecurrentSigmoid`` on the CPU: whole updates (clamp, slot-ordered
weighted sum, sigmoid) of many recurrent sigmoid networks, in one call.

``PopulationRecurrentSigmoid.control_step`` costs a few dozen small tensor ops per update (clamp,
matvec as a float64 cumsum, slope, the portable sigmoid); for the small networks NEAT evolves
per-op overhead sets its speed. The kernel (``snn_torch/kernels/csrc/recurrent_sigmoid.c``) does the
updates in C, rows mapped to networks by an index; its sigmoid is ``portable_math``'s, the torch
path's own, so the two agree bit for bit (tested).
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import Tensor

from snn_torch.kernels.build import library_loader

__all__ = ["sigmoid_kernel_supports", "sigmoid_update_kernel", "SIGMOID_MAX_NODES"]

SIGMOID_MAX_NODES = 1024  # per-row buffers live on the stack
_CSRC = Path(__file__).resolve().parent / "csrc"
_library = library_loader("recurrent_sigmoid", _CSRC / "recurrent_sigmoid.c", _CSRC / "recurrent_sigmoid.h")


def sigmoid_kernel_supports(values: Tensor) -> bool:
    """Whether the kernel can run on ``values``: CPU float32/64 ``[B, N]``, N <= 1024, a built kernel."""
    return (values.device.type == "cpu" and values.dtype in (torch.float32, torch.float64) and values.dim() == 2
            and 1 <= values.shape[1] <= SIGMOID_MAX_NODES and _library() is not None)


def sigmoid_update_kernel(values: Tensor, inputs: Tensor, w_eff: Tensor, network: Tensor | None, *, num_bias: int,
                          slope: float, updates: int) -> Tensor:
    """``updates`` updates ``clamp(sigmoid(slope * ordered_matvec(clamp(values), w)))``: the node
    values ``[B, N]``, where the clamp sets nodes ``0 .. S-1`` to ``inputs [B, S]`` and the next
    ``num_bias`` to 1.

    Trusted: the caller checked shapes, dtypes (``inputs`` and ``w_eff [G, N, N]`` in ``values``'
    dtype) and the network indices (an index outside ``w_eff`` would read outside its memory).
    """
    B, N = values.shape
    values, inputs, w_eff = values.contiguous(), inputs.contiguous(), w_eff.contiguous()
    out = torch.empty_like(values)
    lib = _library()
    fn = lib.sigmoid_update_f32 if values.dtype == torch.float32 else lib.sigmoid_update_f64
    fn(values.data_ptr(), inputs.data_ptr(), w_eff.data_ptr(), None if network is None else network.data_ptr(),
       out.data_ptr(), B, N, inputs.shape[1], num_bias, slope, updates, torch.get_num_threads())
    return out
