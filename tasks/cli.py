"""The ``snn-neat`` command."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# tasks.experiments.cartpole.GA_CHOICES, spelled out so that --help needs no torch (a test
# keeps the two equal).
GA_CHOICES = ("tuned", "neat-c++", "neat-python")


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
    from tasks.experiments.cartpole import (
        controller_config,
        ga_choice,
        markov_config,
        markov_fitness,
        nonmarkov_fitness,
    )

    try:
        device = torch.device(args.device)
        torch.empty(0, device=device)
    except (RuntimeError, AssertionError) as exc:
        raise SystemExit(f"snn-neat evolve: error: --device {args.device!r} is not available ({exc})") from None
    preset, extra = ga_choice("table1" if args.task == "markov" else "table2", args.controller, args.ga)
    if args.task == "markov":
        config = markov_config(args.controller, self_loops=args.self_loops, ga=preset, **extra)
        fitness = markov_fitness(args.controller, config)
    else:
        config = controller_config(args.controller, self_loops=args.self_loops, ga=preset, **extra)
        fitness = nonmarkov_fitness(args.controller, config)
    neat = NEAT(config, seeds=[args.seed], device=device)
    stats = neat.add_reporter(StatisticsReporter())
    neat.add_reporter(StdOutReporter(every=args.report_every) if args.verbose else TqdmReporter(total=args.generations))
    result = neat.run(fitness, args.generations)
    out = args.out
    stats.save_csv(f"{out}/statistics.csv")
    save_genome(f"{out}/champion.json", result.best_genomes, config, fitness=result.best_fitness[0].item())
    solved = result.solved_generation[0].item()
    print(f"{args.controller} seed {args.seed}: best fitness {result.best_fitness[0].item():.0f} steps; "
          + (f"solved at generation {solved}" if solved > 0 else f"not solved in {args.generations} generations")
          + f"; wrote {out}/statistics.csv and {out}/champion.json")
    return 0


def _controllers(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in ("snn", "sigmoid")]
    if not names or bad or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of snn,sigmoid, got {text!r}")
    return names


def _cmd_reproduce(args: argparse.Namespace) -> int:
    import shlex

    import torch

    from tasks.experiments.distributed import has_shards, run_controller_sharded, run_controllers_on_ray
    from tasks.experiments.reproduce import ReproduceError, run_controller, write_report

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    seeds = list(range(args.seed, args.seed + args.runs))
    command = "snn-neat " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["reproduce"] else (
        f"snn-neat reproduce {args.table} --runs {args.runs} --seed {args.seed} --out {args.out}")
    results = {}
    common = dict(resume=args.resume, self_loops=args.self_loops, ga=args.ga, checkpoint_every=args.checkpoint_every,
                  device=args.device, progress=not args.quiet)
    try:
        if args.ray is not None:
            results = run_controllers_on_ray(args.table, args.controllers, seeds, args.generations, args.out,
                                             address=args.ray, shards=args.shards, **common)
        else:
            for c in args.controllers:
                if args.shards is not None or has_shards(args.out, c):  # the shard layout of a (Ray) run
                    results[c] = run_controller_sharded(args.table, c, seeds, args.generations, args.out,
                                                        shards=args.shards, **common)
                else:
                    results[c] = run_controller(args.table, c, seeds, args.generations, args.out, **common)
    except ReproduceError as exc:
        raise SystemExit(f"snn-neat reproduce: error: {exc}") from None
    for path in write_report(results, args.table, args.out, command=command, generalization=not args.no_generalization):
        if path.suffix != ".json" or path.parent.name != "champions":
            print(f"wrote {path}")
    print((Path(args.out) / f"{args.table}.md").read_text())
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
        "evolve", help="evolve one controller on one of the paper's cart-pole tasks",
        description="Evolve one controller (NEAT-SNN or sigmoid NEAT) on a cart-pole task of Qiu et al.: "
                    "nonmarkov (Table II: x and theta only, tau 10 ms, start at 3 degrees, success at 5000 steps) "
                    "or markov (Table I: all four state variables, bang-bang force, tau 20 ms, success at "
                    "100,000 steps). Writes the per-generation statistics and the champion genome.")
    evo.add_argument("--controller", choices=["snn", "sigmoid"], default="snn", help="controller (default: snn)")
    evo.add_argument("--task", choices=["nonmarkov", "markov"], default="nonmarkov",
                     help="task (default: nonmarkov, Table II; markov: Table I)")
    evo.add_argument("--seed", type=_non_negative_int, default=0, help="run seed (default: 0)")
    evo.add_argument("--generations", type=_positive_int, default=100, help="budget (default: 100)")
    evo.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    evo.add_argument("--self-loops", action="store_true",
                     help="start with an output self-connection (neat-python's full start)")
    evo.add_argument("--ga", choices=GA_CHOICES, default="tuned",
                     help="GA settings (default: tuned, the controller's pick for the task; or neat-c++, neat-python)")
    evo.add_argument("--out", default="results/evolve", help="output folder (default: results/evolve)")
    evo.add_argument("--verbose", action="store_true", help="a line per generation instead of a progress bar")
    evo.add_argument("--report-every", type=_positive_int, default=1, help="with --verbose: every N generations")
    evo.set_defaults(func=_cmd_evolve)

    rep = sub.add_parser(
        "reproduce", help="reproduce the paper's Table I or II (NEAT-SNN vs sigmoid NEAT, many seeded runs)",
        description="Reproduce Qiu et al.'s Table I (Markov cart-pole) or Table II (non-Markov): RUNS seeded runs "
                    "(seeds SEED..SEED+RUNS-1) of each controller, all runs of a controller in one batch, with a "
                    "checkpoint after every generation. Writes TABLE.md/.csv (best, worst, median, mean with "
                    "failures as GENERATIONS+1, failure rate, Mann-Whitney U p-value), runs.csv, summary.json, "
                    "fig8_best_fitness.png, trajectory and topology plots and every champion genome.")
    rep.add_argument("table", choices=["table1", "table2"], help="which table to reproduce")
    rep.add_argument("--runs", type=_positive_int, default=60, help="runs per controller (default: 60, the paper's)")
    rep.add_argument("--seed", type=_non_negative_int, default=0, help="first seed (default: 0)")
    rep.add_argument("--generations", type=_positive_int, default=100, help="budget per run (default: 100)")
    rep.add_argument("--controllers", type=_controllers, default=["snn", "sigmoid"],
                     help="comma-separated subset of snn,sigmoid (default: both)")
    rep.add_argument("--self-loops", action="store_true",
                     help="start genomes with an output self-connection (sensitivity check; the paper has none)")
    rep.add_argument("--ga", choices=GA_CHOICES, default="tuned",
                     help="GA settings: 'tuned' (default), each controller's own pick for the table, made on tuning "
                          "seeds; or one preset for both: neat-c++ (NEAT 2002 / NEAT C++) or neat-python (its defaults)")
    rep.add_argument("--out", default=None, help="output folder (default: results/TABLE)")
    rep.add_argument("--resume", action="store_true", help="continue from the checkpoints in --out")
    rep.add_argument("--checkpoint-every", type=_positive_int, default=1, help="generations between checkpoints")
    rep.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    rep.add_argument("--threads", type=_positive_int, default=None, help="torch threads (default: torch's)")
    rep.add_argument("--no-generalization", action="store_true",
                     help="skip the 625-start-state generalisation test of every champion")
    rep.add_argument("--quiet", action="store_true", help="no progress bar")
    rep.add_argument("--ray", default=None, metavar="auto|HOST:PORT",
                     help="run the seeds as Ray tasks on this cluster ('auto': the one `ray start` started on this "
                          "machine); OUT must be on a filesystem all its nodes share (default: run locally)")
    rep.add_argument("--shards", type=_positive_int, default=None,
                     help="split each controller's runs into N shards, one Ray task each (default with --ray: one "
                          "per cluster CPU); a resumed run keeps its split")
    rep.set_defaults(func=_cmd_reproduce)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "command", None) == "reproduce" and args.out is None:
        args.out = f"results/{args.table}"
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
