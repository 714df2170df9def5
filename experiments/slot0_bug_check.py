"""Did the species slot-0 bug move Table II? Rerun it with the bug put back.

    python -m experiments.slot0_bug_check --out results/table2-slot0-bug [--seed 60]

Until the counter-based streams came in, a new species could be founded in slot 0 while
slot 0 still had members: ``_free_slot`` scattered membership flags, and an unassigned
genome's -1 (clamped to slot 0) could overwrite a member's True, so the new species merged
into slot 0. The fix and the new streams landed together, and Table II's NEAT-SNN advantage
went with them. This reruns ``snn-neat reproduce table2`` under the current streams with the
old rule restored, so the two causes can be told apart. The rule lives in the tensor
reference path only, so breeding runs there (``NEAT.fused_breeding = False``; slower).
"""

from __future__ import annotations

import argparse

import torch
from torch import Tensor

import evolution.speciate as speciate_module
from evolution.neat import NEAT
from evolution.speciate import SpeciesState, _first_true
from tasks.studies.cli import main as cli_main


def _free_slot_before_the_fix(species: Tensor, sp: SpeciesState, need: Tensor) -> tuple[Tensor, SpeciesState]:
    """``_free_slot`` as it was: membership by a scatter of flags (last write wins)."""
    while True:
        taken = torch.zeros_like(sp.alive)
        taken.scatter_(1, species.clamp_min(0), species >= 0)
        slot, has_slot = _first_true(~taken)
        if not bool((need & ~has_slot).any()):
            return slot, sp
        sp = sp.grow(2 * sp.capacity)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    ap.add_argument("--runs", type=int, default=60)
    args = ap.parse_args(argv)
    speciate_module._free_slot = _free_slot_before_the_fix
    NEAT.fused_breeding = False
    return cli_main(["reproduce", "table2", "--runs", str(args.runs), "--seed", str(args.seed), "--out", args.out])


if __name__ == "__main__":
    raise SystemExit(main())
