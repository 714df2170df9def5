"""Closed-loop spiking throughput and peak memory against batch size R x P and network size N.

    python benchmarks/scale.py                         # CPU: R x P up to 1e6, N in {8, 16, 32, 64}
    python benchmarks/scale.py --quick                 # a few small points
    python benchmarks/scale.py --device cuda           # the torch path on a GPU, compiled
    python benchmarks/scale.py --torch-path --compile on   # the CUDA code path, timed on the CPU

Workload: the non-Markov cart-pole through the task seam (``evolution.rollout``: plant,
encoder, 20 Izhikevich substeps per control step, weighted-rate decoder) on random recurrent networks of N nodes (connection
probability 0.4), fixed episodes of ``--steps`` control steps (failure limits lifted so every
row runs the whole episode). Batches larger than the memory budget (``--max-memory`` MiB for
the weight tensor ``[B, N, N]``) are evaluated in chunks, one after another; a row's result
does not depend on its chunk. CPU runs the network in its C kernel (``--threads``); CUDA
uses the batched torch path (``--torch-path`` takes it on the CPU too),
its substeps compiled by ``torch.compile`` (``--compile``: auto compiles on CUDA only; the
compilation is paid once, before the timed rows, and printed separately). Prints
genome-steps/s, neuron-substeps/s, chunks and peak memory (process RSS on CPU, max
allocated on CUDA).
"""

from __future__ import annotations

import argparse
import math
import resource
import time

import torch

from evolution.config import NEATConfig
from evolution.phenotype import make_controller
from evolution.population import Genomes
from evolution.rollout import rollout
from tasks.cartpole import CartPoleParams, CartPoleTask

NO_FAIL = CartPoleParams(x_limit=1e30, theta_limit=1e30)
TASK = CartPoleTask.nonmarkov(plant=NO_FAIL)
SUBSTEPS = 20


def random_chunk(rows: int, n: int, seed: int, device: str) -> tuple[Genomes, NEATConfig]:
    cfg = NEATConfig(num_inputs=2, num_outputs=1, num_bias=0, max_hidden=n - 3, pop_size=rows)
    g = torch.Generator().manual_seed(seed)
    conn = torch.rand(1, rows, n, n, generator=g) < 0.4
    conn[..., :, :2] = False
    w = torch.randn(1, rows, n, n, generator=g) * 2.0
    genomes = Genomes(weight=w, conn=conn, enabled=conn.clone(), node=torch.ones(1, rows, n, dtype=torch.bool),
                      sigma=torch.full((1, rows), 0.005))
    return genomes.to(device), cfg


def run(total: int, n: int, steps: int, max_memory_mib: float, device: str, *, torch_path: bool = False,
        compile_step: bool | None = None) -> tuple[float, int]:
    """Seconds for ``total`` rows in chunks under the memory budget; returns (seconds, chunks)."""
    per_row = n * n * 4 * 4  # weight, conn, enabled, effective weight: ~4 [N, N] tensors per row
    chunk = max(1, min(total, int(max_memory_mib * 2**20 // per_row)))
    chunks = math.ceil(total / chunk)
    elapsed = 0.0
    for k in range(chunks):
        rows = min(chunk, total - k * chunk)
        genomes, cfg = random_chunk(rows, n, k, device)
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        backend = "auto" if not torch_path else ("compiled" if compile_step or (compile_step is None and
                                                                               device.startswith("cuda")) else "torch")
        policy = make_controller(genomes, cfg, TASK, backend=backend)
        done = rollout(TASK, policy, max_steps=steps).steps
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        elapsed += time.perf_counter() - t0
        assert int(done.min()) == steps
        del genomes, policy
    return elapsed, chunks


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--steps", type=int, default=100, help="control steps per episode (default 100)")
    parser.add_argument("--max-memory", type=float, default=1024.0, help="MiB per chunk (default 1024)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--points", default=None,
                        help="rows to time, as R x P 'x' N, comma separated (e.g. 1000000x8,9000x32)")
    parser.add_argument("--torch-path", action="store_true",
                        help="the batched torch loop (what CUDA runs) instead of the CPU's C kernel")
    parser.add_argument("--compile", choices=["auto", "on", "off"], default="auto",
                        help="torch.compile the torch path's substep (auto: on CUDA only)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch_path = args.torch_path or not args.device.startswith("cpu")
    compile_step = {"auto": None, "on": True, "off": False}[args.compile]
    compiles = torch_path and (compile_step or (compile_step is None and args.device.startswith("cuda")))
    if compiles:  # one graph serves every batch and network size: compile it before the timed rows
        t0 = time.perf_counter()
        run(2, 8, 1, args.max_memory, args.device, torch_path=True, compile_step=True)
        print(f"torch.compile of the substep, paid once: {time.perf_counter() - t0:.1f} s")
    if args.points:
        try:
            points = [tuple(int(v) for v in item.lower().split("x")) for item in args.points.split(",")]
        except ValueError:
            parser.error(f"--points must look like 1000000x8,9000x32, got {args.points!r}")
        if any(len(pt) != 2 or pt[0] < 1 or pt[1] < 3 for pt in points):
            parser.error(f"--points must look like 1000000x8,9000x32 (at least 1 network of at least 3 nodes: "
                         f"2 inputs and the output), got {args.points!r}")
    elif args.quick:
        points = [(150, 8), (9000, 8), (9000, 32)]
    else:
        points = [(150, 8), (9000, 8), (100_000, 8), (1_000_000, 8), (9000, 16), (9000, 32), (9000, 64),
                  (100_000, 32), (100_000, 64)]
    path = ("torch path, compiled" if compiles else "torch path, eager") if torch_path else "seam, C network kernel"
    print(f"device {args.device} ({path}), {args.threads} thread(s), {args.steps} control steps x {SUBSTEPS} "
          f"substeps, chunks of at most {args.max_memory:.0f} MiB")
    header = f"{'R x P':>10}{'N':>5}{'chunks':>8}{'genome-steps/s':>16}{'neuron-substeps/s':>19}{'peak MiB':>10}"
    print(header)
    print("-" * len(header))
    for total, n in points:
        if args.device.startswith("cuda"):
            torch.cuda.reset_peak_memory_stats()
        seconds, chunks = run(total, n, args.steps, args.max_memory, args.device, torch_path=torch_path,
                              compile_step=compile_step)
        rate = total * args.steps / seconds
        if args.device.startswith("cuda"):
            peak = torch.cuda.max_memory_allocated() / 2**20
        else:
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
        print(f"{total:>10}{n:>5}{chunks:>8}{rate:>16.3g}{rate * n * SUBSTEPS:>19.3g}{peak:>10.0f}")


if __name__ == "__main__":
    main()
