"""This toolkit against neat-python on the same closed-loop workload, side by side.

    python benchmarks/compare_neat_python.py            # R x P = 150 and 9000, one thread
    python benchmarks/compare_neat_python.py --quick    # 150 only, shorter episodes

Workload (issue 8): the paper's non-Markov cart-pole (inputs x and theta, tau 10 ms), a
fixed set of random recurrent networks of 8 nodes (2 inputs, 1 output, 5 hidden; each of
the 64 possible connections present with probability 0.4, weights N(0, 2)), a fixed episode
length (the failure limits are lifted so no episode ends early and both sides do the same
number of steps). Spiking: 20 Izhikevich substeps of 0.5 ms per control step on both
sides (neat-python's ``iznn``: its own Euler scheme, inputs as currents; ours: Heun with a
sub-step reset). Sigmoid: one network update per control step (neat-python's
``RecurrentNetwork``). neat-python loops over genomes in Python, so its time is linear in
the number of genomes; it runs a subset (``--py-genomes``) and its per-genome rate is
scaled to the batch, which the table says.

Needs neat-python (``pip install -e ".[bench]"``). Prints genome-steps/s, neuron-substeps/s
and the ratio; medians of ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import torch

from evolution.config import NEATConfig
from evolution.phenotype import make_controller
from evolution.population import Genomes
from evolution.rollout import rollout
from tasks.cartpole import CartPoleParams, CartPoleTask

N_NODES, N_IN, OUT = 8, 2, 2  # node 2 is the output, 3..7 hidden
SUBSTEPS = 20
TAU = 0.01
NO_FAIL = CartPoleParams(x_limit=1e30, theta_limit=1e30)  # fixed-length episodes


def random_genomes(batch: int, seed: int = 0) -> tuple[Genomes, NEATConfig]:
    cfg = NEATConfig(num_inputs=2, num_outputs=1, num_bias=0, max_hidden=N_NODES - 3, pop_size=batch)
    g = torch.Generator().manual_seed(seed)
    conn = torch.rand(1, batch, N_NODES, N_NODES, generator=g) < 0.4
    conn[..., :, :N_IN] = False  # nothing feeds an input
    w = torch.randn(1, batch, N_NODES, N_NODES, generator=g) * 2.0
    node = torch.ones(1, batch, N_NODES, dtype=torch.bool)
    sigma = torch.full((1, batch), 0.005)
    return Genomes(weight=w, conn=conn, enabled=conn.clone(), node=node, sigma=sigma), cfg


TASK = CartPoleTask.nonmarkov(plant=NO_FAIL)


def ours(kind: str, genomes: Genomes, cfg: NEATConfig, steps: int, backend: str = "auto") -> float:
    """Seconds for one episode of every genome through the task seam (``evolution.rollout``)."""
    controller = make_controller(genomes, cfg, TASK, kind, backend=backend)
    t0 = time.perf_counter()
    done = rollout(TASK, controller, max_steps=steps).steps
    elapsed = time.perf_counter() - t0
    assert int(done.min()) == steps, "an episode ended early"
    return elapsed


def plant_step(s: list[float], force: float, tau: float = TAU) -> list[float]:
    # The same explicit Euler as tasks.cartpole, in Python floats (what a neat-python user writes).
    x, xd, th, thd = s
    total, mp, length = 1.1, 0.1, 0.5
    sn, cs = math.sin(th), math.cos(th)
    temp = (-force - mp * length * thd * thd * sn) / total
    thacc = (9.8 * sn + cs * temp) / (length * (4.0 / 3.0 - mp * cs * cs / total))
    xacc = (force + mp * length * (thd * thd * sn - thacc * cs)) / total
    return [x + tau * xd, xd + tau * xacc, th + tau * thd, thd + tau * thacc]


def _norm(s: list[float]) -> list[float]:
    return [min(max((s[0] / 2.4 + 1) * 0.5, 0.0), 1.0), min(max((s[2] / math.radians(12) + 1) * 0.5, 0.0), 1.0)]


def neat_python(kind: str, genomes: Genomes, count: int, steps: int) -> float:
    """Seconds for ``count`` genomes, each one episode of ``steps`` control steps."""
    from neat.activations import sigmoid_activation
    from neat.aggregations import sum_aggregation
    from neat.iznn import CHATTERING_PARAMS, IZNN, IZNeuron
    from neat.nn import RecurrentNetwork

    w = genomes.effective_weight()[0, :count]
    nets = []
    for k in range(count):
        links = {j: [(i, float(w[k, i, j])) for i in range(N_NODES) if w[k, i, j] != 0] for j in range(N_IN, N_NODES)}
        inputs, outputs = [0, 1], [OUT]
        if kind == "snn":
            neurons = {j: IZNeuron(30.0, inputs=links[j], **CHATTERING_PARAMS) for j in range(N_IN, N_NODES)}
            nets.append(IZNN(neurons, inputs, outputs))
        else:
            evals = [(j, sigmoid_activation, sum_aggregation, 0.0, 1.0, links[j]) for j in range(N_IN, N_NODES)]
            nets.append(RecurrentNetwork(inputs, outputs, evals))
    t0 = time.perf_counter()
    for net in nets:
        s = [0.0, 0.0, math.radians(3.0), 0.0]
        for _ in range(steps):
            if kind == "snn":
                net.set_inputs([60.0 * v for v in _norm(s)])
                fired = 0.0
                for _ in range(SUBSTEPS):
                    fired += net.advance(0.5)[0]
                force = 10.0 * (2.0 / (1.0 + math.exp(-0.005 * fired * 100.0)) - 1.0)
            else:
                force = 10.0 * (2.0 * net.activate(_norm(s))[0] - 1.0)
            s = plant_step(s, force)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="150 only, 200-step episodes")
    parser.add_argument("--steps", type=int, default=1000, help="control steps per episode (default 1000)")
    parser.add_argument("--py-genomes", type=int, default=30, help="genomes neat-python runs (default 30)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    steps = 200 if args.quick else args.steps
    sizes = [150] if args.quick else [150, 9000]
    try:
        import neat  # noqa: F401
        have_neat = True
    except ImportError:
        have_neat = False
        print("neat-python not installed (pip install -e '.[bench]'): showing this toolkit only")
    print(f"closed loop, {N_NODES} nodes, {steps} control steps per episode, {SUBSTEPS} substeps (spiking), "
          f"{args.threads} thread(s), median of {args.repeats}")
    header = (f"{'controller':<10}{'R x P':>8}{'path':>26}{'genome-steps/s':>16}{'neuron-substeps/s':>19}"
              f"{'vs neat-python':>16}")
    print(header)
    print("-" * len(header))
    compiled_once = False
    for kind in ("snn", "sigmoid"):
        for B in sizes:
            genomes, cfg = random_genomes(B)
            py_rate = None
            if have_neat:
                count = min(args.py_genomes, B)
                py_steps = max(20, steps // 5) if kind == "snn" else steps
                t = statistics.median(neat_python(kind, genomes, count, py_steps) for _ in range(args.repeats))
                py_rate = count * py_steps / t
                nss = f"{py_rate * N_NODES * SUBSTEPS:.3g}" if kind == "snn" else "-"
                print(f"{kind:<10}{B:>8}{f'neat-python ({count} genomes)':>26}{py_rate:>16.3g}{nss:>19}{'1.0x':>16}")
            # The torch path is what CUDA runs; compiled (spiking only), it is CUDA's default.
            # Both networks: the C kernel (the CPU's default) and the eager torch path (what runs
            # with no C compiler); spiking ones also the compiled torch step (CUDA's default).
            paths = [("seam, C kernel", "auto"), ("seam, torch eager", "torch"), ("seam, torch compiled", "compiled")]
            if kind == "sigmoid":
                paths = paths[:2]
            for name, backend in paths:
                if kind == "snn" and backend == "torch" and B > 150:
                    continue  # the spiking eager path at 9000 takes minutes
                if backend == "compiled" and not compiled_once:  # paid once per process, before the timed runs
                    compiled_once = True
                    t0 = time.perf_counter()
                    ours(kind, genomes.gather(torch.zeros(1, 2, dtype=torch.long)), cfg, 1, "compiled")
                    print(f"{'':<18}(torch.compile of the substep: {time.perf_counter() - t0:.1f} s)")
                t = statistics.median(ours(kind, genomes, cfg, steps, backend) for _ in range(args.repeats))
                rate = B * steps / t
                nss = f"{rate * N_NODES * SUBSTEPS:.3g}" if kind == "snn" else "-"
                ratio = f"{rate / py_rate:.0f}x" if py_rate else "-"
                print(f"{kind:<10}{B:>8}{name:>26}{rate:>16.3g}{nss:>19}{ratio:>16}")
    print("targets (issue 8, one thread, 9000 x 8 nodes): spiking >= 2e8 neuron-substeps/s, "
          "sigmoid >= 2e7 genome-steps/s; at 150, spiking >= 10x neat-python")


if __name__ == "__main__":
    main()
