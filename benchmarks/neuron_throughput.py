"""Neuron-substep updates per second of the population-batched recurrent Izhikevich layer.

One "neuron-substep" is one neuron advanced by one integration step of ``dt_ms``, including
its share of the batched recurrent matmul. Prints a table of medians over repeats for
P in {150, 9000, 100000} networks of N in {8, 32} neurons (random 30 %-dense masks), on the
CPU with one thread and with all threads, and on CUDA when present.

    python benchmarks/neuron_throughput.py            # full table
    python benchmarks/neuron_throughput.py --quick    # small sizes, a smoke run
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import torch

from snn_torch import PopulationRecurrentIzhikevich


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def measure(P: int, N: int, *, device: str, method: str, steps: int, repeats: int) -> float:
    """Median neuron-substeps/s over ``repeats`` runs of ``steps`` substeps."""
    g = torch.Generator().manual_seed(0)
    weight = torch.randn(P, N, N, generator=g) * 5.0
    mask = torch.rand(P, N, N, generator=g) < 0.3
    layer = PopulationRecurrentIzhikevich(weight, mask, i_background=5.0, method=method).to(device)
    current = (torch.rand(1, P, N, generator=g) * 10.0).to(device).expand(steps, -1, -1)
    layer(current[:2])  # warm-up: allocator, kernels
    times = []
    for _ in range(repeats):
        _sync(device)
        start = time.perf_counter()
        layer(current)
        _sync(device)
        times.append(time.perf_counter() - start)
    return P * N * steps / statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="small sizes only (a smoke run)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--methods", default="heun,euler", help="comma-separated integration methods")
    args = parser.parse_args()

    sizes = [(150, 8), (150, 32)] if args.quick else [(p, n) for p in (150, 9000, 100000) for n in (8, 32)]
    all_threads = os.cpu_count() or 1
    configs = [("cpu", 1), ("cpu", all_threads)]
    if torch.cuda.is_available():
        configs.append(("cuda", all_threads))
    methods = args.methods.split(",")

    print(f"torch {torch.__version__}, {all_threads} CPU threads available"
          + (f", CUDA: {torch.cuda.get_device_name()}" if torch.cuda.is_available() else ", no CUDA"))
    header = f"{'device':>6} {'threads':>7} {'P':>7} {'N':>3} " + " ".join(f"{m + ' (upd/s)':>16}" for m in methods)
    print(header)
    print("-" * len(header))
    for device, threads in configs:
        torch.set_num_threads(threads)
        for P, N in sizes:
            # Enough substeps for ~0.2 s of work at 1e8 upd/s, at least 10.
            steps = max(10, min(400, int(2e7 / (P * N))))
            rates = [measure(P, N, device=device, method=m, steps=steps, repeats=args.repeats) for m in methods]
            print(f"{device:>6} {threads:>7} {P:>7} {N:>3} " + " ".join(f"{r:>16.3e}" for r in rates), flush=True)


if __name__ == "__main__":
    main()
