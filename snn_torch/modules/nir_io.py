"""NIR (Neuromorphic Intermediate Representation) export and import for LIF / LI / Linear chains.

``export_nir(model)`` turns an ``nn.Sequential`` of ``LIF``, ``LI`` and ``nn.Linear`` (each
possibly wrapped in ``Stateful``) into a ``nir.NIRGraph``; a layer becomes its input projection
(``nir.Affine``, or ``nir.Linear`` without bias) followed by ``nir.LIF`` / ``nir.LI``.
``import_nir(graph)`` builds the ``nn.Sequential`` of ``Stateful`` layers back. NIR's
neuron equations are ``snn_torch.functional.lif``'s; its time constants are in seconds
(``tau_mem_ms / 1000``), and the step ``dt_ms`` travels in the graph's metadata.
Two differences NIR leaves to the simulator: snn_torch spikes at ``v >= v_threshold`` (NIR
writes ``>``), and ``LIF(reset="subtract")`` has no NIR node, so its export is refused.

Needs the optional ``nir`` package: ``pip install "snn-neat[nir]"``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from snn_torch.functional.lif import LIFParams, LIParams
from snn_torch.modules.lif import LI, LIF
from snn_torch.modules.stateful import Stateful

__all__ = ["export_nir", "import_nir"]


def _nir() -> Any:
    try:
        import nir
    except ImportError as err:  # optional dependency
        raise ImportError('NIR export/import needs the nir package: pip install "snn-neat[nir]"') from err
    return nir


def _array(t: torch.Tensor, n: int) -> np.ndarray:
    return np.broadcast_to(t.detach().double().cpu().numpy(), (n,)).copy()


def _projection(nir: Any, linear: nn.Linear) -> Any:
    w = linear.weight.detach().double().cpu().numpy()
    if linear.bias is None:
        return nir.Linear(weight=w)
    return nir.Affine(weight=w, bias=linear.bias.detach().double().cpu().numpy())


def export_nir(model: nn.Module) -> Any:
    """A ``nir.NIRGraph`` of ``model``: an ``nn.Sequential`` (or one layer) of LIF, LI and ``nn.Linear``.

    Raises ``ValueError`` naming a module NIR cannot hold here (Izhikevich, recurrent layers,
    ``reset="subtract"``) or layers with different ``dt_ms``.
    """
    nir = _nir()
    modules = list(model) if isinstance(model, nn.Sequential) else [model]
    nodes, dts = [], set()
    for index, module in enumerate(modules):
        layer = module.layer if isinstance(module, Stateful) else module
        if type(layer) is nn.Linear:
            nodes.append(_projection(nir, layer))
        elif type(layer) in (LIF, LI):
            n = layer.linear.out_features
            nodes.append(_projection(nir, layer.linear))
            tau_s = _array(layer.tau_mem_ms, n) / 1000.0
            r, v_leak = _array(layer.r, n), _array(layer.v_leak, n)
            if type(layer) is LIF:
                if layer.reset != "zero":
                    raise ValueError(f"module {index} (LIF) has reset={layer.reset!r}: NIR's LIF resets to v_reset")
                nodes.append(nir.LIF(tau=tau_s, r=r, v_leak=v_leak, v_threshold=_array(layer.v_th, n),
                                     v_reset=_array(layer.v_reset, n)))
            else:
                nodes.append(nir.LI(tau=tau_s, r=r, v_leak=v_leak))
            dts.add(layer.dt_ms)
        else:
            raise ValueError(f"module {index} ({type(layer).__name__}) has no NIR export here; "
                             "supported: LIF, LI, nn.Linear (bare or in Stateful)")
    if len(dts) > 1:
        raise ValueError(f"the layers step with different dt_ms {sorted(dts)}; NIR's graph gets one")
    graph = nir.NIRGraph.from_list(*nodes)
    if dts:
        graph.metadata["dt_ms"] = dts.pop()
    return graph


def _chain(graph: Any) -> list[Any]:
    """The graph's nodes from its single input to its single output, or ``ValueError``."""
    nir = _nir()
    succ: dict[str, list[str]] = {}
    for a, b in graph.edges:
        succ.setdefault(a, []).append(b)
    starts = [k for k, node in graph.nodes.items() if isinstance(node, nir.Input)]
    if len(starts) != 1:
        raise ValueError(f"the graph must have one Input node, has {len(starts)}")
    chain, name = [], starts[0]
    while True:
        nxt = succ.get(name, [])
        if len(nxt) != 1:
            if not nxt and isinstance(graph.nodes[name], nir.Output):
                return chain
            raise ValueError(f"node {name!r} has {len(nxt)} successors: only chains import here")
        name = nxt[0]
        if isinstance(graph.nodes[name], nir.Output):
            return chain
        chain.append((name, graph.nodes[name]))
        if len(chain) > len(graph.nodes):
            raise ValueError("the graph has a cycle: recurrent graphs do not import here")


def _linear(node: Any, dtype: torch.dtype) -> nn.Linear:
    weight = torch.as_tensor(np.asarray(node.weight), dtype=dtype)
    bias = getattr(node, "bias", None)
    linear = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None, dtype=dtype)
    with torch.no_grad():
        linear.weight.copy_(weight)
        if bias is not None:
            linear.bias.copy_(torch.as_tensor(np.asarray(bias), dtype=dtype))
    return linear


def import_nir(graph: Any, *, dt_ms: float | None = None, dtype: torch.dtype = torch.float32) -> nn.Sequential:
    """An ``nn.Sequential`` of ``Stateful`` LIF/LI layers and ``nn.Linear`` from a NIR chain.

    Args:
        graph: a ``nir.NIRGraph`` (for example ``nir.read(path)``).
        dt_ms: step length (ms); default the graph's ``metadata["dt_ms"]``, else required.
        dtype: parameter dtype.

    Call ``reset_states(model)`` between sequences. Raises ``ValueError`` naming an
    unsupported node.
    """
    nir = _nir()
    if dt_ms is None:
        dt_ms = graph.metadata.get("dt_ms") if isinstance(graph.metadata, dict) else None
        if dt_ms is None:
            raise ValueError("the graph carries no metadata['dt_ms']: pass dt_ms (ms)")
    layers: list[nn.Module] = []
    pending: nn.Linear | None = None
    for name, node in _chain(graph):
        if isinstance(node, (nir.Affine, nir.Linear)):
            if pending is not None:
                layers.append(pending)
            pending = _linear(node, dtype)
            continue
        if not isinstance(node, (nir.LIF, nir.LI)):
            raise ValueError(f"node {name!r} is a {type(node).__name__}: supported are Affine, Linear, LIF, LI")
        if pending is None:
            raise ValueError(f"node {name!r} ({type(node).__name__}) must follow an Affine or Linear node")

        def t(values: Any) -> torch.Tensor:
            return torch.as_tensor(np.asarray(values, dtype=np.float64), dtype=dtype)

        tau_ms = torch.as_tensor(np.asarray(node.tau, dtype=np.float64) * 1000.0, dtype=dtype)
        if isinstance(node, nir.LIF):
            p = LIFParams(tau_mem_ms=tau_ms, v_leak=t(node.v_leak), v_th=t(node.v_threshold),
                          v_reset=t(node.v_reset), r=t(node.r))
            layer = LIF(pending.in_features, pending.out_features, p, bias=pending.bias is not None, dt_ms=dt_ms,
                        dtype=dtype)
        else:
            p_li = LIParams(tau_mem_ms=tau_ms, v_leak=t(node.v_leak), r=t(node.r))
            layer = LI(pending.in_features, pending.out_features, p_li, bias=pending.bias is not None,
                       dt_ms=dt_ms, dtype=dtype)
        layer.linear = pending
        layers.append(Stateful(layer))
        pending = None
    if pending is not None:
        layers.append(pending)
    return nn.Sequential(*layers)
