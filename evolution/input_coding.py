"""How observations become a network's inputs: one definition for the rollout and the C episode loop.

A task declares bounds ``[low, high]`` for each observed variable (its own units). A controller's
spec picks the coding (``SpikingSpec.input_coding``, ``SigmoidSpec.input_coding``):

- ``"unit"``: ``(x - low) / (high - low)`` clipped to [0, 1], one input node per variable (the
  paper's coding, and the default). The middle of the range is 0.5, so a network at rest on a
  balanced plant already receives drive from every input.
- ``"signed"``: ``(x - mid) / half`` with ``mid = (low + high) / 2`` and ``half = (high - low) / 2``,
  in [-1, 1] (clipped unless ``clip_inputs=False``), one input node per variable: 0 at the
  middle of the range, as NEAT 1.2.1 codes the pole-balancing state (x / 4.8, theta / 0.52, ...
  over bounds of +-4.8 m, +-0.52 rad, ...). A spiking current encoder then injects a negative
  current below the middle (its rate falls below the background's); a Bernoulli encoder cannot
  (a spike probability is not negative): use ``"push_pull"``.
- ``"push_pull"``: the signed value ``s`` on two input nodes per variable, ``max(s, 0)`` and
  ``max(-s, 0)`` (variable ``k``'s pair at nodes ``2k`` and ``2k + 1``): both silent (at the
  background rate) in the middle of the range, one or the other driven away from it, as an
  ON/OFF pair of sensory neurons codes a signed quantity with non-negative rates.

The constants are computed once in the network's dtype (``coding_constants``), and the C loop
(``evolution/kernels/csrc/episodes_impl.h``, ``lanes_observe_``) repeats these operations on them, so
both paths give the same bits.
"""

from __future__ import annotations

import torch
from torch import Tensor

from snn_torch.functional.scalars import scalars

__all__ = ["INPUT_CODINGS", "CODING_CODES", "inputs_per_observation", "check_coding", "coding_constants",
           "code_observations", "input_coding_of"]

INPUT_CODINGS = ("unit", "signed", "push_pull")
CODING_CODES = {"unit": 0, "signed": 1, "push_pull": 2}  # the C episode loop's


def input_coding_of(controller) -> tuple[str, bool]:
    """``(input_coding, clip_inputs)`` of a controller (``Controller.input_coding``), checked;
    ``("unit", True)`` for a controller that does not say."""
    coding, clip = getattr(controller, "input_coding", ("unit", True))
    check_coding(type(controller).__name__, coding, clip)
    return coding, clip


def inputs_per_observation(coding: str) -> int:
    """Input nodes per observed variable: 2 for ``"push_pull"``, else 1."""
    return 2 if coding == "push_pull" else 1


def check_coding(owner: str, coding: str, clip: bool) -> None:
    """``ValueError`` naming ``owner``'s field for an unknown coding or an unclipped unit coding."""
    if coding not in INPUT_CODINGS:
        raise ValueError(f"{owner}.input_coding must be one of {INPUT_CODINGS}, got {coding!r}")
    if not isinstance(clip, bool):
        raise ValueError(f"{owner}.clip_inputs must be a bool, got {clip!r}")
    if coding == "unit" and not clip:
        raise ValueError(f"{owner}.clip_inputs=False needs input_coding 'signed' or 'push_pull' (the unit coding "
                         "is clipped to [0, 1])")


def coding_constants(low: Tensor, high: Tensor, coding: str) -> tuple[Tensor, Tensor]:
    """``(offset, scale)`` ``[observations]`` in ``low``'s dtype: ``(low, high - low)`` for the unit
    coding, ``(mid, half)`` for the signed ones (computed in float64 from the bounds, then rounded)."""
    if coding == "unit":
        return low, high - low
    lo, hi = low.to(torch.float64), high.to(torch.float64)
    return ((lo + hi) * 0.5).to(low.dtype), ((hi - lo) * 0.5).to(low.dtype)


def code_observations(obs: Tensor, offset: Tensor, scale: Tensor, coding: str, clip: bool) -> Tensor:
    """``[B, observations]`` observations in ``offset``'s dtype -> ``[B, inputs]`` network inputs."""
    x = (obs - offset) / scale
    zero, one, minus_one = scalars((0.0, 1.0, -1.0), x)  # cached 0-dim tensors: no allocation per control step
    if coding == "unit":
        return torch.clamp(x, zero, one)
    if clip:
        x = torch.clamp(x, minus_one, one)
    if coding == "signed":
        return x
    return torch.stack([torch.where(x > 0, x, zero), torch.where(x < 0, -x, zero)], -1).flatten(1)
