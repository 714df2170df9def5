"""The ``snn-neat`` command."""

from __future__ import annotations

import argparse
import sys
import time


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _cmd_figures(args: argparse.Namespace) -> int:
    from snn_torch.plots import save_neuron_figures

    start = time.perf_counter()
    paths = save_neuron_figures(args.out, dt_ms=args.dt_ms)
    for path in paths:
        print(f"wrote {path}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def _int_at_least(minimum: int):
    """An argparse type: an integer >= ``minimum``."""
    what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def _cmd_xor(args: argparse.Namespace) -> int:
    from tasks.experiments.xor import run_xor, write_xor_report

    seeds = list(range(args.seed, args.seed + args.runs))
    summary = run_xor(seeds, generations=args.generations, device=args.device)
    for path in write_xor_report(summary, args.out):
        print(f"wrote {path}")
    t = summary.table()
    print(f"{t['runs']} runs (seeds {seeds[0]}..{seeds[-1]}): {t['failures']} failures, mean "
          f"{t['mean_generations']:.2f} generations, median {t['median_generations']}, mean hidden nodes "
          f"{t['mean_hidden_nodes']:.2f}; {t['wall_s']:.1f} s")
    return 0


def _cmd_evolve(args: argparse.Namespace) -> int:
    import torch

    from evolution.genome_io import save_genome
    from evolution.neat import NEAT
    from evolution.reporters import StatisticsReporter, StdOutReporter, TqdmReporter
    from tasks.experiments.cartpole import controller_config, nonmarkov_fitness

    try:
        device = torch.device(args.device)
        torch.empty(0, device=device)
    except (RuntimeError, AssertionError) as exc:
        raise SystemExit(f"snn-neat evolve: error: --device {args.device!r} is not available ({exc})") from None
    config = controller_config(args.controller, self_loops=args.self_loops)
    neat = NEAT(config, seeds=[args.seed], device=device)
    stats = neat.add_reporter(StatisticsReporter())
    neat.add_reporter(StdOutReporter(every=args.report_every) if args.verbose else TqdmReporter(total=args.generations))
    result = neat.run(nonmarkov_fitness(args.controller, config), args.generations)
    out = args.out
    stats.save_csv(f"{out}/statistics.csv")
    save_genome(f"{out}/champion.json", result.best_genomes, config, fitness=result.best_fitness[0].item())
    solved = result.solved_generation[0].item()
    print(f"{args.controller} seed {args.seed}: best fitness {result.best_fitness[0].item():.0f} steps; "
          + (f"solved at generation {solved}" if solved > 0 else f"not solved in {args.generations} generations")
          + f"; wrote {out}/statistics.csv and {out}/champion.json")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="snn-neat", description="Evolving spiking neural networks in PyTorch.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    fig = sub.add_parser(
        "figures", help="regenerate the paper's neuron figures (Fig. 1 and Fig. 2) as PNG",
        description="Regenerate Qiu et al.'s Fig. 1 (voltage response to a square current) and "
                    "Fig. 2 (f-I curve, I from 0 to 200) as PNG files.")
    fig.add_argument("--out", default="figures", help="output folder (default: figures)")
    fig.add_argument("--dt-ms", type=_positive_float, default=0.02,
                     help="integration step in ms (default: 0.02)")
    fig.set_defaults(func=_cmd_figures)

    xor = sub.add_parser(
        "xor", help="NEAT sanity check: evolve XOR over many seeded runs (Stanley & Miikkulainen 2002)",
        description="Evolve XOR with sigmoid tensor NEAT, one run per seed (seeds SEED..SEED+RUNS-1), all "
                    "runs in one batch; write runs.csv, summary.json and summary.md.")
    xor.add_argument("--runs", type=_positive_int, default=100, help="number of runs (default: 100)")
    xor.add_argument("--seed", type=_non_negative_int, default=0, help="first seed (default: 0)")
    xor.add_argument("--generations", type=_positive_int, default=100, help="budget per run (default: 100)")
    xor.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    xor.add_argument("--out", default="results/xor", help="output folder (default: results/xor)")
    xor.set_defaults(func=_cmd_xor)

    evo = sub.add_parser(
        "evolve", help="evolve one controller on the paper's non-Markov cart-pole",
        description="Evolve one controller (NEAT-SNN or sigmoid NEAT) on the non-Markov cart-pole of Qiu et "
                    "al. (x and theta only, tau 10 ms, start at 3 degrees, success at 5000 steps). Writes the "
                    "per-generation statistics and the champion genome.")
    evo.add_argument("--controller", choices=["snn", "sigmoid"], default="snn", help="controller (default: snn)")
    evo.add_argument("--task", choices=["nonmarkov"], default="nonmarkov",
                     help="task (default: nonmarkov; the Markov task is not implemented yet)")
    evo.add_argument("--seed", type=_non_negative_int, default=0, help="run seed (default: 0)")
    evo.add_argument("--generations", type=_positive_int, default=100, help="budget (default: 100)")
    evo.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    evo.add_argument("--self-loops", action="store_true",
                     help="start with an output self-connection (neat-python's full start)")
    evo.add_argument("--out", default="results/evolve", help="output folder (default: results/evolve)")
    evo.add_argument("--verbose", action="store_true", help="a line per generation instead of a progress bar")
    evo.add_argument("--report-every", type=_positive_int, default=1, help="with --verbose: every N generations")
    evo.set_defaults(func=_cmd_evolve)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
