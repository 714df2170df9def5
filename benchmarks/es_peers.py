"""The evolution-strategy peers of ``benchmarks/classic_control_vs_es.py``: a batched MLP
controller, EvoTorch's PGPE and an OpenES, on this project's batched torch plants.

* ``MLP``: a fully connected network ``sizes[0]-...-sizes[-1]`` (hidden activation ``tanh`` or
  ``relu``), its parameters one flat vector per member: per layer the weight ``[fan_in, fan_out]``
  (row-major), then the bias ``[fan_out]``. Its head, as the peers configure theirs: on a
  ``Discrete(n)`` port (``task.discrete = n``) ``n`` logits and the greedy action, their argmax
  ``k`` (the first on a tie); on a ``Box`` port one ``tanh`` output per action, scaled by
  ``task.action_max``.
* ``MLPController``: ``G`` members' MLPs as an ``evolution.task.Controller``, so
  ``evolution.rollout.rollout`` runs every member x every episode as one batch through
  ``task.reset``/``step``/``observe``, exactly as it feeds NEAT-SNN and sigmoid NEAT (finished
  episodes frozen, then dropped). A ``Discrete(n)`` port takes one action in ``[-1, 1]`` and bins
  it itself (``tasks.gym_adapter.discrete_action``), so the argmax ``k`` is fed as the centre of
  bin ``k``, ``bin_centres(n)[k] = -1 + (2k + 1) / n``, which the port bins back to ``k``
  exactly (``n = 2``: -0.5, 0.5; ``n = 3``: -2/3, 0, 2/3 to rounding). The layers run as ``torch.baddbmm``
  over the members (each member's episodes a ``[E, fan_in]`` block), no Python loop over members.
  Inputs: the port's raw observations (``raw_observations=True``), or the observations
  normalised by the port's bounds, ``(obs - mid) / half`` with ``mid``, ``half`` the middle and
  half-width of ``[observation_low, observation_high]``, unclipped (the ``"signed"`` coding our
  controllers use, without their clip to [-1, 1]).
* ``peer_returns``: ``[G, E]`` float64 returns of ``G`` members (``[G, N]`` parameters).
* ``PGPE``: EvoTorch's functional PGPE (``evotorch.algorithms.functional.pgpe``, ClipUp,
  centered ranks, symmetric sampling) behind ``ask``/``tell``/``center``, its sampling on a
  random stream of its own (seeded; the global one is left as it was).
* ``OpenES``: OpenAI-ES as evosax 0.1.x implements it (``evosax/strategies/open_es.py``,
  ``evosax/utils/optimizer.py``, ``evosax/utils/reshape_fitness.py``, the version
  RobertTLange/gymnax-blines trained with): antithetic sampling around the mean (zeros at
  first), centered ranks, optional weight decay, Adam on the mean, exponentially decaying
  sigma and learning rate with floors.

Units: returns are the task's (sum of rewards per episode); episodes are whole episodes of
``task.max_steps`` control steps at most.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from evolution.rollout import episode_starts, rollout
from evolution.task import Task

__all__ = ["MLP", "MLPController", "bin_centres", "peer_returns", "centered_ranks", "PGPE", "OpenES"]


def bin_centres(n: int, dtype: torch.dtype = torch.float32) -> Tensor:
    """``[n]``: the centre of each of ``discrete_action``'s ``n`` bins of ``[-1, 1]``,
    ``-1 + (2k + 1) / n`` (computed in float64, then rounded to ``dtype``): the value a
    ``Discrete(n)`` port bins to action ``k``."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"bin_centres needs a positive int n, got {n!r}")
    k = torch.arange(n, dtype=torch.float64)
    return (-1.0 + (2.0 * k + 1.0) / n).to(dtype)


@dataclass(frozen=True)
class MLP:
    """A fully connected net: ``sizes`` (inputs, hidden..., outputs), ``hidden`` activation
    ("tanh" or "relu"). ``discrete``: ``n`` of a ``Discrete(n)`` action (then ``sizes[-1] = n``
    logits and the greedy action, their argmax), or 0: ``tanh`` outputs, scaled by the task's
    ``action_max``."""

    sizes: tuple[int, ...]
    hidden: str = "tanh"
    discrete: int = 0

    def __post_init__(self) -> None:
        if len(self.sizes) < 2 or any(int(s) < 1 for s in self.sizes):
            raise ValueError(f"MLP.sizes must be at least (inputs, outputs), all positive, got {self.sizes!r}")
        if self.hidden not in ("tanh", "relu"):
            raise ValueError(f"MLP.hidden must be 'tanh' or 'relu', got {self.hidden!r}")
        if isinstance(self.discrete, bool) or not isinstance(self.discrete, int) or self.discrete < 0 or \
                (self.discrete and self.sizes[-1] != self.discrete):
            raise ValueError(f"MLP.discrete must be 0 or n >= 1 with n = sizes[-1] outputs (logits), got "
                             f"{self.discrete!r} with sizes {self.sizes!r}")

    @classmethod
    def for_task(cls, task: Task, hidden_sizes: Sequence[int], hidden: str) -> MLP:
        """``observations-hidden...-outputs`` for ``task``: ``n`` logits on a ``Discrete(n)``
        port (``task.discrete``), one output per action on a ``Box`` one."""
        n = _discrete(task)
        outputs = n if n else task.action_size
        return cls((task.observation_size, *(int(h) for h in hidden_sizes), outputs), hidden, n)

    @property
    def num_params(self) -> int:
        """Weights and biases of one member."""
        return sum(i * o + o for i, o in zip(self.sizes[:-1], self.sizes[1:], strict=True))

    def layers(self, params: Tensor) -> list[tuple[Tensor, Tensor]]:
        """``[G, N]`` flat parameters -> per layer ``(weight [G, fan_in, fan_out], bias [G, 1, fan_out])``."""
        if params.dim() != 2 or params.shape[1] != self.num_params:
            raise ValueError(f"MLP {self.sizes}: parameters must be [G, {self.num_params}], got {tuple(params.shape)}")
        out, at = [], 0
        for i, o in zip(self.sizes[:-1], self.sizes[1:], strict=True):
            w = params[:, at:at + i * o].reshape(-1, i, o)
            at += i * o
            b = params[:, at:at + o].reshape(-1, 1, o)
            at += o
            out.append((w, b))
        return out


def _discrete(task: Task) -> int:
    """``n`` of ``task``'s ``Discrete(n)`` action (``GymTask``'s and the ports' ``discrete``), 0 for a ``Box``."""
    n = int(getattr(task, "discrete", 0) or 0)
    if n and task.action_size != 1:
        raise ValueError(f"task {task.name!r}: a Discrete({n}) task must take one action, got {task.action_size}")
    return n


@dataclass
class _Rows:
    """The controller's state of the rows in the batch: each row's member and episode slot,
    the members with rows here (``live``, sorted), each row's index into ``live`` and those
    members' layers. ``full``: the rows are all ``G * E`` of them in rollout order."""

    member: Tensor
    slot: Tensor
    live: Tensor
    inverse: Tensor
    layers: list[tuple[Tensor, Tensor]]
    full: bool


class MLPController:
    """``G`` members' MLPs as a ``Controller`` of ``evolution.task`` (module docstring).

    Args:
        mlp: the architecture; params: ``[G, mlp.num_params]``; task: the plant (its bounds and
            ``action_max``); raw_observations: undo the rollout's normalisation, so the net
            sees the port's observations as they are (False: normalised by the bounds).
    """

    def __init__(self, mlp: MLP, params: Tensor, task: Task, *, raw_observations: bool) -> None:
        n = _discrete(task)
        outputs = n if n else task.action_size
        if mlp.sizes[0] != task.observation_size or mlp.sizes[-1] != outputs or mlp.discrete != n:
            raise ValueError(f"MLP {mlp.sizes} (discrete {mlp.discrete}) does not fit task {task.name!r} "
                             f"({task.observation_size} observations, "
                             + (f"Discrete({n}): {n} logits)" if n else f"{task.action_size} actions)"))
        self.mlp, self.raw = mlp, bool(raw_observations)
        self._params = params.detach().to(torch.float32)
        self.num_genomes = int(params.shape[0])
        self._layers = mlp.layers(self._params)
        low, high = (t.to(torch.float64) for t in task.bounds(dtype=torch.float64))
        self._mid = ((low + high) * 0.5).to(torch.float32)
        self._half = ((high - low) * 0.5).to(torch.float32)
        self._action_max = torch.tensor(float(task.action_max), dtype=torch.float32)
        self._centres = bin_centres(n).to(self._params.device) if n else None  # action k's value in [-1, 1]
        self._episodes = 1

    @property
    def dtype(self) -> torch.dtype:
        return torch.float32

    @property
    def device(self) -> torch.device:
        return self._params.device

    @property
    def input_coding(self) -> tuple[str, bool]:
        return ("signed", False)  # (obs - mid) / half, unclipped: an affine map the net may undo

    def _rows(self, member: Tensor, slot: Tensor, full: bool) -> _Rows:
        live, inverse = torch.unique(member, sorted=True, return_inverse=True)
        layers = self._layers if full else [(w[live], b[live]) for w, b in self._layers]
        return _Rows(member, slot, live, inverse, layers, full)

    def initial_state(self, network: Tensor) -> _Rows:
        B = int(network.shape[0])
        if B % self.num_genomes:
            raise ValueError(f"MLPController: {B} rows is not a whole number of episodes per member")
        self._episodes = max(1, B // self.num_genomes)
        slot = torch.arange(B, device=network.device) % self._episodes
        expected = torch.arange(B, device=network.device) // self._episodes
        return self._rows(network, slot, bool(torch.equal(network, expected)))

    def select(self, state: _Rows, keep: Tensor) -> _Rows:
        return self._rows(state.member[keep], state.slot[keep], False)

    def act(self, inputs: Tensor, state: _Rows) -> tuple[Tensor, _Rows, Tensor]:
        x = inputs.to(torch.float32)
        if self.raw:
            x = x * self._half + self._mid
        E = self._episodes
        if state.full:
            h = x.view(self.num_genomes, E, -1)
        else:  # each live member's rows in a [E, fan_in] block (rows of finished episodes stay zero)
            h = x.new_zeros(state.live.shape[0], E, x.shape[1])
            h[state.inverse, state.slot] = x
        last = len(state.layers) - 1
        for k, (w, b) in enumerate(state.layers):
            h = torch.baddbmm(b, h, w)
            if k < last:
                h = torch.tanh(h) if self.mlp.hidden == "tanh" else torch.relu(h)
        if self._centres is None:
            out = torch.tanh(h) * self._action_max
        else:  # the greedy action k of the n logits, as the centre of the port's bin k: [., E, 1]
            out = self._centres[h.argmax(-1, keepdim=True)]
        action = out.reshape(-1, out.shape[-1]) if state.full else out[state.inverse, state.slot]
        return action, state, action.detach()


def peer_returns(task: Task, mlp: MLP, params: Tensor, *, episodes: int, seed: int | None = None, starts=None,
                 raw_observations: bool) -> Tensor:
    """``[G, episodes]`` float64 returns of the ``G`` members ``params`` (``[G, N]``), every
    member from the same ``episodes`` starts (``starts``, or ``task.reset`` seeded by ``seed``),
    all ``G * episodes`` episodes as one batch (``evolution.rollout.rollout``)."""
    if starts is None:
        if seed is None:
            raise ValueError("peer_returns needs seed= or starts=")
        starts = episode_starts(task, episodes, seed, dtype=torch.float32)
    controller = MLPController(mlp, params, task, raw_observations=raw_observations)
    return rollout(task, controller, episodes=episodes, starts=starts).fitness(task.fitness)


def centered_ranks(fitness: Tensor) -> Tensor:
    """``[P]`` utilities in [-0.5, 0.5]: the worst member -0.5, the best +0.5, linear in rank
    (ties in index order, as evosax's ``centered_rank_trafo`` and EvoTorch's "centered")."""
    P = fitness.shape[0]
    ranks = torch.empty(P, dtype=torch.float64)
    ranks[torch.argsort(fitness, stable=True)] = torch.arange(P, dtype=torch.float64)
    return ranks / max(1, P - 1) - 0.5


class PGPE:
    """EvoTorch's functional PGPE (``pgpe``, ``pgpe_ask``, ``pgpe_tell``), maximising, from a
    zero centre, with ClipUp (``center_learning_rate``, ``max_speed``, ``momentum``), centered
    ranks, symmetric sampling, ``radius_init`` (the initial stdev vector's norm),
    ``stdev_learning_rate`` and ``stdev_max_change``. Sampling draws from a random stream of its
    own, seeded by ``seed``."""

    def __init__(self, num_params: int, *, popsize: int, center_learning_rate: float, max_speed: float,
                 momentum: float, radius_init: float, stdev_learning_rate: float, stdev_max_change: float,
                 seed: int) -> None:
        from evotorch.algorithms.functional import pgpe

        self.popsize = int(popsize)
        self.state = pgpe(center_init=torch.zeros(num_params, dtype=torch.float32),
                          center_learning_rate=center_learning_rate, stdev_learning_rate=stdev_learning_rate,
                          objective_sense="max", ranking_method="centered", optimizer="clipup",
                          optimizer_config={"max_speed": max_speed, "momentum": momentum},
                          radius_init=radius_init, stdev_max_change=stdev_max_change, symmetric=True)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            self._rng = torch.get_rng_state()

    def ask(self) -> Tensor:
        """``[popsize, N]`` members (symmetric pairs around the centre)."""
        from evotorch.algorithms.functional import pgpe_ask

        with torch.random.fork_rng(devices=[]):
            torch.set_rng_state(self._rng)
            x = pgpe_ask(self.state, popsize=self.popsize)
            self._rng = torch.get_rng_state()
        return x

    def tell(self, x: Tensor, fitness: Tensor) -> None:
        """Update from the members ``x`` and their fitness ``[popsize]`` (higher is better)."""
        from evotorch.algorithms.functional import pgpe_tell

        self.state = pgpe_tell(self.state, x, fitness.to(x.dtype))

    @property
    def center(self) -> Tensor:
        """``[N]``: the search distribution's centre."""
        return self.state.optimizer_state.center


class OpenES:
    """OpenAI-ES as evosax 0.1.x (module docstring), maximising ``fitness``.

    ``ask``: ``popsize / 2`` normal directions ``z`` and their negatives, ``x = mean + sigma z``.
    ``tell``: fitness less ``w_decay * mean(x^2)`` (evosax's ``FitnessShaper`` weight decay),
    centered ranks ``u``, the gradient ``z^T u / (popsize sigma)`` followed by Adam
    (``beta_1``, ``beta_2``, ``eps``, bias-corrected) with learning rate ``lrate``; then
    ``lrate = max(lrate * lrate_decay, lrate_limit)``, ``sigma = max(sigma * sigma_decay,
    sigma_limit)``. The mean starts at zero (evosax's ``init_min = init_max = 0``)."""

    def __init__(self, num_params: int, *, popsize: int, sigma_init: float, sigma_decay: float, sigma_limit: float,
                 lrate_init: float, lrate_decay: float, lrate_limit: float, beta_1: float = 0.99,
                 beta_2: float = 0.999, eps: float = 1e-8, w_decay: float = 0.0, seed: int) -> None:
        if popsize < 2 or popsize % 2:
            raise ValueError(f"OpenES.popsize must be even and at least 2 (antithetic pairs), got {popsize!r}")
        self.popsize, self.w_decay = int(popsize), float(w_decay)
        self.sigma, self.sigma_decay, self.sigma_limit = float(sigma_init), float(sigma_decay), float(sigma_limit)
        self.lrate, self.lrate_decay, self.lrate_limit = float(lrate_init), float(lrate_decay), float(lrate_limit)
        self.beta_1, self.beta_2, self.eps = float(beta_1), float(beta_2), float(eps)
        self.mean = torch.zeros(num_params, dtype=torch.float64)
        self.m, self.v, self.t = torch.zeros_like(self.mean), torch.zeros_like(self.mean), 0
        self.generator = torch.Generator().manual_seed(int(seed))

    def ask(self) -> Tensor:
        """``[popsize, N]`` members: ``mean + sigma z`` for ``z`` and ``-z``."""
        z = torch.randn(self.popsize // 2, self.mean.shape[0], generator=self.generator, dtype=torch.float64)
        return self.mean + self.sigma * torch.cat([z, -z])

    def tell(self, x: Tensor, fitness: Tensor) -> None:
        """Update the mean from the members ``x`` and their fitness ``[popsize]`` (higher is better)."""
        x, f = x.to(torch.float64), fitness.to(torch.float64)
        if self.w_decay > 0.0:
            f = f - self.w_decay * (x * x).mean(1)
        u = centered_ranks(f)
        z = (x - self.mean) / self.sigma
        grad = -(z.T @ u) / (self.popsize * self.sigma)  # of the loss -fitness, as evosax descends
        self.t += 1
        self.m = (1.0 - self.beta_1) * grad + self.beta_1 * self.m
        self.v = (1.0 - self.beta_2) * grad * grad + self.beta_2 * self.v
        m_hat = self.m / (1.0 - self.beta_1 ** self.t)
        v_hat = self.v / (1.0 - self.beta_2 ** self.t)
        self.mean = self.mean - self.lrate * m_hat / (torch.sqrt(v_hat) + self.eps)
        self.lrate = max(self.lrate * self.lrate_decay, self.lrate_limit)
        self.sigma = max(self.sigma * self.sigma_decay, self.sigma_limit)

    @property
    def center(self) -> Tensor:
        """``[N]``: the mean."""
        return self.mean
