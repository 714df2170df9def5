"""Memory ablation: any controller of the seam run as a memoryless map of its current observation.

``StaticMapController(controller, settle_steps)`` wraps a ``SpikingController`` or
``SigmoidController`` (anything with ``initial_state``, ``act`` and ``select``): every control
step starts the network from its initial state and acts ``settle_steps`` times on the current
observation; the last action is applied and nothing carries to the next step. A champion that
balances as evolved but not as a static map uses state carried across control steps, which is
where a controller that is never given velocities must get them from.
"""

from __future__ import annotations

from torch import Tensor

__all__ = ["StaticMapController"]


class StaticMapController:
    """``controller`` as a memoryless map of the observation (see the module docstring).

    Args:
        controller: the controller of the genomes (``evolution.phenotype.make_controller``).
        settle_steps: control steps the fresh network runs on each observation before its
            action is taken (for spiking controllers, enough to fill the rate window).
    """

    def __init__(self, controller, settle_steps: int = 20) -> None:
        if isinstance(settle_steps, bool) or not isinstance(settle_steps, int) or settle_steps < 1:
            raise ValueError(f"settle_steps must be an int >= 1, got {settle_steps!r}")
        self.controller, self.settle_steps = controller, settle_steps

    def __getattr__(self, name: str):  # num_genomes, dtype, device, input_coding, ...: the wrapped controller's
        if name == "controller":  # not set yet (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.controller, name)

    def initial_state(self, network: Tensor):
        return self.controller.initial_state(network)

    def select(self, state, keep: Tensor):
        return self.controller.select(state, keep)

    def act(self, obs01: Tensor, state):
        fresh = self.controller.initial_state(state.network)
        for _ in range(self.settle_steps):
            action, fresh, activity = self.controller.act(obs01, fresh)
        return action, state, activity
