"""Checks the layer modules run once at their boundary (``validate=True``), with errors that name
the argument, the expected type or shape, and what was given.

Shape, type and dtype checks are static, so they trace under ``torch.compile(fullgraph=True)``;
the finite check reads the data, so it is skipped while compiling (a graph break otherwise).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import torch
from torch import Tensor, nn

__all__ = ["check_input", "check_state", "neuron_parameters", "params_for_step"]


def check_input(name: str, x: object, *, min_dim: int, features: int | None, dtype: torch.dtype | None,
                layout: str) -> Tensor:
    """Raise ``ValueError`` naming ``name`` unless ``x`` is a finite tensor shaped ``layout``."""
    if not isinstance(x, Tensor):
        raise ValueError(f"{name} must be a torch.Tensor shaped {layout}, got {type(x).__name__}")
    if x.dim() < min_dim or (features is not None and x.shape[-1] != features):
        raise ValueError(f"{name} must be {layout}, got shape {tuple(x.shape)}")
    if dtype is not None and x.dtype != dtype:
        raise ValueError(f"{name} has dtype {x.dtype}, but the layer's parameters are {dtype}: "
                         f"convert one of them (x.to({dtype}) or layer.to({x.dtype}))")
    if not torch.compiler.is_compiling() and not bool(torch.isfinite(x).all()):
        raise ValueError(f"{name} holds NaN or inf")
    return x


def check_state(state: object, cls: type[NamedTuple], shape: torch.Size | None, like: object) -> None:
    """Raise ``TypeError``/``ValueError`` unless ``state`` is a ``cls`` of tensors shaped ``shape``
    (``None``: all shaped like its first field), with the tensor ``like``'s dtype and device."""
    name = cls.__name__
    if not isinstance(state, cls):
        got = type(state).__name__
        hint = f" (wrap it: snn_torch.{name}(*state))" if isinstance(state, tuple) else ""
        raise TypeError(f"state must be a snn_torch.{name}{cls._fields}, got {got}{hint}")
    for field, value in zip(cls._fields, state, strict=True):
        if not isinstance(value, Tensor):
            raise TypeError(f"{name}.{field} must be a torch.Tensor, got {type(value).__name__}")
        shape = value.shape if shape is None else shape
        if value.shape != shape:
            raise ValueError(f"{name}.{field} has shape {tuple(value.shape)}, but this input needs "
                             f"{tuple(shape)} (batch dims, then neurons)")
        if not isinstance(like, Tensor):
            continue
        if value.dtype != like.dtype:
            raise ValueError(f"{name}.{field} has dtype {value.dtype}, but the input is {like.dtype}")
        if value.device != like.device:
            raise ValueError(f"{name}.{field} is on {value.device}, but the input is on {like.device}")


def neuron_parameters(module: nn.Module, params: NamedTuple, learn: bool | tuple[str, ...] | list[str],
                      *, device: torch.device | str | None, dtype: torch.dtype | None) -> None:
    """Register every field of ``params`` on ``module`` as an ``nn.Parameter`` of that name.

    Fields named in ``learn`` (or all, with ``learn=True``), and fields given as tensors that
    require grad, require grad; the others do not but
    still follow ``.to()`` and ``state_dict``. Floats become 0-dim tensors; tensors keep their
    shape (for example ``[N]``, one value per neuron).
    """
    fields = type(params)._fields
    wanted = set(fields) if learn is True else set() if learn is False else set(learn)
    # A tensor that already requires grad (an nn.Parameter in the params tuple) is meant to be learned.
    wanted |= {f for f, v in zip(fields, params, strict=True) if isinstance(v, Tensor) and v.requires_grad}
    unknown = wanted - set(fields)
    if unknown:
        raise ValueError(f"learn_params names unknown fields {sorted(unknown)}; fields are {list(fields)}")
    dtype = dtype if dtype is not None else torch.get_default_dtype()
    for field, value in zip(fields, params, strict=True):
        data = value.detach().clone() if isinstance(value, Tensor) else torch.tensor(float(value))
        data = data.to(device=device, dtype=dtype)
        module.register_parameter(field, nn.Parameter(data, requires_grad=field in wanted))


def params_for_step(params: NamedTuple, dtype: torch.dtype) -> Any:
    """``params`` (a NamedTuple of tensors) ready for a step on ``dtype`` tensors.

    Each tensor is cast to ``dtype``. A 0-dim CPU tensor that needs no gradient becomes a Python
    float holding the same ``dtype`` value: the step's scalar arithmetic then stays in Python
    instead of launching an aten op per use (the same bits: a float operand is rounded to the
    tensor's dtype). Kept as tensors while compiling (no ``.item()`` in the graph).
    """
    compiling = torch.compiler.is_compiling()
    out = []
    for t in params:
        t = t if t.dtype == dtype else t.to(dtype)
        if not compiling and t.dim() == 0 and t.device.type == "cpu" and not (t.requires_grad and
                                                                               torch.is_grad_enabled()):
            t = t.item()
        out.append(t)
    return type(params)(*out)
