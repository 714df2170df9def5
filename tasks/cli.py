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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
