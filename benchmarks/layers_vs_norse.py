"""snn_torch's spiking layers beside Norse's and snnTorch's, in one process, on one thread.

Each row is ``Linear(128 -> 256)`` followed by 256 spiking neurons, run for the same
simulated time (``--sim-ms``). Printed per step and per simulated ms (each model has its own
step): forward (``torch.no_grad``), forward + backward (a fixed random readout of the spikes),
and the bytes autograd keeps for the backward (``saved_tensors_hooks``, each storage counted
once; the Linear's own input and weight are left out, they are the same for every row).
Medians over ``--repeats`` rounds, the rows interleaved within each round, because this
machine is shared.

Norse's Izhikevich steps 0.25 ms (``dt=0.001`` times its hidden ``tau_inv=250``), with forward
Euler and an end-of-step reset; snn_torch's default steps 0.5 ms with Heun and a sub-step
reset (see docs/numerics.md, "Integration scheme"). ``euler`` rows use Norse's scheme and step.
A peer that is not installed is skipped (``pip install -e ".[bench]"`` installs both).

    python benchmarks/layers_vs_norse.py [--batches 64 1024] [--sim-ms 25] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import torch
from torch import nn

import snn_torch
from snn_torch.functional import QIU2019

IN, OUT = 128, 256


def _norse():
    try:
        import norse.torch as norse
    except Exception:  # not installed, or an import error of its own: skip the peer
        return None
    return norse


def _snntorch():
    try:
        import snntorch
    except Exception:
        return None
    return snntorch


class Row:
    """A model to time: ``run(x) -> spikes`` and its step length (ms)."""

    def __init__(self, name: str, step_ms: float, build: Callable[[], tuple[nn.Module, Callable]]):
        self.name, self.step_ms = name, step_ms
        self.model, self.run = build()


def _linear(scale: float, bias: float) -> nn.Linear:
    lin = nn.Linear(IN, OUT)
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        lin.weight.copy_(torch.randn(OUT, IN, generator=g) * scale)
        lin.bias.fill_(bias)
    return lin


def rows() -> list[Row]:
    out = []

    def ours_izh(method: str, dt_ms: float, substep_reset: bool, fused: bool = True):
        def build():
            layer = snn_torch.Izhikevich(IN, OUT, QIU2019, dt_ms=dt_ms, method=method, substep_reset=substep_reset,
                                         fused=fused, validate=False)
            layer.linear = _linear(0.6, 8.0)
            return layer, lambda x: layer(x)[0]
        return build

    out.append(Row("snn_torch Izhikevich heun 0.5ms", 0.5, ours_izh("heun", 0.5, True)))
    out.append(Row("snn_torch Izhikevich heun 0.5ms unfused", 0.5, ours_izh("heun", 0.5, True, fused=False)))
    out.append(Row("snn_torch Izhikevich euler 0.25ms", 0.25, ours_izh("euler", 0.25, False)))
    norse = _norse()
    if norse is not None:
        def build_norse_izh():
            lin, neurons = _linear(0.6, 8.0), norse.Izhikevich(norse.tonic_bursting, dt=0.001)  # a .02 b .2 c -50 d 2
            model = nn.ModuleList([lin, neurons])
            return model, lambda x: neurons(lin(x))[0]
        out.append(Row("norse Izhikevich euler 0.25ms", 0.25, build_norse_izh))

        def build_norse_izh_cells():
            # Norse's cell stepped over current.unbind(0): its neuron arithmetic without its SNN loop,
            # whose per-step input[t] costs a full-size zero-filled gradient each in the backward.
            lin, cell = _linear(0.6, 8.0), norse.IzhikevichCell(norse.tonic_bursting, dt=0.001)

            def run(x):
                state, spikes = None, []
                for i_t in lin(x).unbind(0):
                    z, state = cell(i_t, state)
                    spikes.append(z)
                return torch.stack(spikes)
            return nn.ModuleList([lin, cell]), run
        out.append(Row("norse IzhikevichCell over unbind 0.25ms", 0.25, build_norse_izh_cells))
    if hasattr(snn_torch, "LIF"):
        def build_lif():
            layer = snn_torch.LIF(IN, OUT, dt_ms=1.0, validate=False)
            layer.linear = _linear(0.3, 0.2)
            return layer, lambda x: layer(x)[0]
        out.append(Row("snn_torch LIF 1ms", 1.0, build_lif))
    if norse is not None:
        def build_norse_lif():
            lin = _linear(0.3, 0.2)
            # Norse's LIF has a synaptic current too (tau_syn 5 ms); tau_mem 10 ms, 1 ms steps
            neurons = norse.LIF(norse.LIFParameters(tau_mem_inv=torch.as_tensor(100.0)), dt=1e-3)
            model = nn.ModuleList([lin, neurons])
            return model, lambda x: neurons(lin(x))[0]
        out.append(Row("norse LIF 1ms", 1.0, build_norse_lif))
    snntorch = _snntorch()
    if snntorch is not None:
        def build_leaky():
            import math
            lin, neurons = _linear(0.3, 0.2), snntorch.Leaky(beta=math.exp(-0.1))  # 10 ms at 1 ms steps

            def run(x):
                cur, mem, spikes = lin(x), None, []
                mem = neurons.init_leaky()
                for t in range(cur.shape[0]):
                    spk, mem = neurons(cur[t], mem)
                    spikes.append(spk)
                return torch.stack(spikes)
            return nn.ModuleList([lin, neurons]), run
        out.append(Row("snntorch Leaky 1ms", 1.0, build_leaky))
    return out


def saved_bytes(row: Row, x: torch.Tensor) -> int:
    """Bytes autograd keeps for backward in ``row.run(x)``, each storage once, less x and the weights."""
    skip = {x.untyped_storage().data_ptr()} | {p.untyped_storage().data_ptr() for p in row.model.parameters()}
    seen: dict[int, int] = {}

    def pack(t: torch.Tensor) -> torch.Tensor:
        s = t.untyped_storage()
        if s.data_ptr() not in skip:
            seen[s.data_ptr()] = s.nbytes()
        return t

    with torch.autograd.graph.saved_tensors_hooks(pack, lambda t: t):
        row.run(x)
    return sum(seen.values())


def ops_per_step(row: Row, x: torch.Tensor) -> float:
    """aten operations per step of a no-grad forward (the Linear over all steps included)."""
    from torch.utils._python_dispatch import TorchDispatchMode

    class Count(TorchDispatchMode):
        n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            Count.n += 1
            return func(*args, **(kwargs or {}))

    with torch.no_grad(), Count():
        row.run(x)
    return Count.n / x.shape[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[64, 1024])
    parser.add_argument("--sim-ms", type=float, default=25.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--keep-freed-memory", action="store_true",
                        help="raise glibc's mmap/trim thresholds first (snn_torch._malloc), for every row")
    args = parser.parse_args()
    if args.keep_freed_memory:
        from snn_torch._malloc import keep_freed_memory
        keep_freed_memory()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    table = rows()
    print(f"torch {torch.__version__}, {args.threads} thread(s), Linear {IN} -> {OUT} neurons, "
          f"{args.sim_ms:g} simulated ms, median of {args.repeats}")
    for batch in args.batches:
        xs, readouts = {}, {}
        for row in table:
            steps = round(args.sim_ms / row.step_ms)
            g = torch.Generator().manual_seed(2)
            xs[row.name] = torch.rand(steps, batch, IN, generator=g)
            readouts[row.name] = torch.randn(steps, batch, OUT, generator=g)
        fwd: dict[str, list[float]] = {r.name: [] for r in table}
        fb: dict[str, list[float]] = {r.name: [] for r in table}
        rates: dict[str, float] = {}
        for rep in range(args.repeats + 1):  # round 0 warms up
            for row in table:
                x, w = xs[row.name], readouts[row.name]
                t0 = time.perf_counter()
                with torch.no_grad():
                    z = row.run(x)
                t1 = time.perf_counter()
                row.model.zero_grad(set_to_none=True)
                t2 = time.perf_counter()
                (row.run(x) * w).sum().backward()
                t3 = time.perf_counter()
                if rep:
                    fwd[row.name].append(t1 - t0)
                    fb[row.name].append(t3 - t2)
                rates[row.name] = z.mean().item() / row.step_ms * 1000.0
        print(f"\nbatch {batch}")
        print(f"| {'model':<40} | step ms | fwd us/step | fwd+bwd us/step | fwd us/ms | fwd+bwd us/ms "
              f"| saved KiB/ms | rate Hz | aten ops/step |")
        print("|" + "---|" * 9)
        for row in table:
            steps = xs[row.name].shape[0]
            f, b = statistics.median(fwd[row.name]) * 1e6, statistics.median(fb[row.name]) * 1e6
            mem = saved_bytes(row, xs[row.name]) / args.sim_ms / 1024
            print(f"| {row.name:<40} | {row.step_ms:g} | {f / steps:.0f} | {b / steps:.0f} | {f / args.sim_ms:.0f} | "
                  f"{b / args.sim_ms:.0f} | {mem:.0f} | {rates[row.name]:.0f} | "
                  f"{ops_per_step(row, xs[row.name]):.1f} |")


if __name__ == "__main__":
    main()
