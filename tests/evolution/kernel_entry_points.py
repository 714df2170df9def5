"""Entry points into the C kernels that only the tests use.

They live in a library of their own (``tests/csrc/kernel_entry_points.c``, exports declared
in ``kernel_entry_points.h``), built the first time a test asks, so the package neither ships
nor compiles them. They reach the production kernels' code through the shared headers
(``box_muller.h``, ``gene_distance.h``), so what they check is what the kernels run.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import torch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.kernels import breed as breed_kernel
from evolution.kernels.breed import GeneBits, _sfx, breed_params, gene_set
from snn_torch.kernels.build import KernelLibrary, KernelStruct, load_library

__all__ = ["library", "gene_distances", "DistancesIO"]

_CSRC = Path(__file__).resolve().parents[1] / "csrc"
_KERNEL_HEADERS = Path(breed_kernel.__file__).resolve().parent / "csrc"  # box_muller.h, gene_distance.h
LIBRARY = ("neat_kernel_tests", _CSRC / "kernel_entry_points.c", _CSRC / "kernel_entry_points.h")


class DistancesIO(KernelStruct):
    """``distances_io`` of ``kernel_entry_points.h``: the rows compared, and the output."""
    _fields_ = [("rows_a", ctypes.c_void_p), ("Ka", ctypes.c_int64), ("rows_b", ctypes.c_void_p),
                ("Kb", ctypes.c_int64), ("R", ctypes.c_int64), ("NN", ctypes.c_int64), ("W", ctypes.c_int64),
                ("out", ctypes.c_void_p), ("threads", ctypes.c_int)]


def library() -> KernelLibrary | None:
    """The test library (``normals_check``, ``distances_f32``/``_f64``), or None without a compiler."""
    return load_library(*LIBRARY, include_dirs=[_KERNEL_HEADERS])


def gene_distances(a: GeneBits, rows_a: Tensor, b: GeneBits, rows_b: Tensor, cfg: NEATConfig) -> Tensor:
    """Distances ``[R, Ka, Kb]`` (float64) between rows ``rows_a[R, Ka]`` of ``a`` and
    ``rows_b[R, Kb]`` of ``b`` (flat row indices), as ``evolution.distance.distance``: the
    distance code of ``breed_kernel.assign_species``."""
    lib = library()
    if lib is None:
        raise RuntimeError("the C test kernels are unavailable (no compiler, or SNN_NEAT_C_KERNELS=0)")
    R, Ka = rows_a.shape
    Kb = rows_b.shape[1]
    out = torch.empty(R, Ka, Kb, dtype=torch.float64)
    if R * Ka * Kb == 0:
        return out
    ra, rb = rows_a.contiguous(), rows_b.contiguous()
    io = DistancesIO(rows_a=ra.data_ptr(), Ka=Ka, rows_b=rb.data_ptr(), Kb=Kb, R=R, NN=a.nn, W=a.words,
                     out=out.data_ptr(), threads=torch.get_num_threads())
    getattr(lib, f"distances_{_sfx(a.weight.dtype)}")(ctypes.byref(breed_params(cfg)), ctypes.byref(gene_set(a)),
                                                      ctypes.byref(gene_set(b)), ctypes.byref(io))
    return out
