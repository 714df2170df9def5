"""Weight search on a fixed topology with EvoTorch: any task (``evolution.task.Task``) as an EvoTorch ``Problem``.

NEAT finds a topology; any EvoTorch Gaussian searcher (SNES, XNES, CEM, PGPE, CMA-ES) can then
tune its weights. ``FixedTopologyProblem`` fixes a connection mask ``[N, N]`` (a NEAT
champion's enabled genes, or a mask of your own) and searches

    solution = (w_1, ..., w_C, ln sigma)

the weights of the ``C`` connections in the mask, in row-major ``(from, to)`` order
(``problem.connections``), then, for the spiking controller, the natural log of its decoder
gain ``sigma`` (the sigmoid controller has no gain: its solutions hold the weights only).

Why ln sigma: sigma must stay positive and its useful values span decades (NEAT-SNN starts
at 0.005), while EvoTorch's Gaussian searchers accept no bounds and use one step size scale
for all coordinates. In log space a step of 0.5 multiplies sigma by 1.65 whatever its size,
and no sample is ever negative. Decoding then clamps weights to the config's
``[weight_min_value, weight_max_value]`` and sigma to ``[sigma_min_value, sigma_max_value]``,
so a searched vector is always a valid genome, and ``to_genomes`` returns exactly the genome
that was evaluated.

Fitness (maximised): the task's fitness (return or steps survived), up to ``max_steps``,
averaged over ``starts``: by default the task's own start (``task.reset``); for robustness,
any fixed set, e.g. the cart-pole's 625 of ``tasks.studies.generalization.start_grid()``.
``_evaluate_batch`` runs the whole EvoTorch population x all starts as one rollout
(``evolution.rollout``), no Python loop over solutions.

Usage, fine-tuning a NEAT-SNN champion for robustness::

    import torch
    from evotorch.algorithms import SNES
    from evotorch.logging import PandasLogger, StdOutLogger
    from evolution import load_genome, save_genome
    from evolution.weight_search import FixedTopologyProblem
    from tasks.cartpole import CartPoleTask
    from tasks.studies.cartpole import controller_config
    from tasks.studies.generalization import start_grid, success_rate

    config = controller_config("snn")
    champion = load_genome("champion.json", config)          # [1, 1] Genomes
    grid = start_grid()                                      # 625 start states
    # train on a random quarter of the grid, report on all of it
    train = grid[torch.randperm(625, generator=torch.Generator().manual_seed(0))[:156]]
    problem = FixedTopologyProblem.from_genome(champion, config, task=CartPoleTask.nonmarkov(), starts=train,
                                                max_steps=1000, seed=0)
    searcher = SNES(problem, popsize=32, stdev_init=0.3, center_init=problem.initial_solution())
    StdOutLogger(searcher, interval=10)
    log = PandasLogger(searcher)
    searcher.run(200)
    tuned = problem.to_genomes(searcher.status["center"])
    print(success_rate(champion, config), success_rate(tuned, config))   # before, after
    save_genome("tuned.json", tuned, config)

(``success_rate`` counts a start as balanced at 1000 steps, Gruau et al.'s criterion.)
Small tensors run fastest with ``torch.set_num_threads(1)`` and parallelism across
processes (``num_actors``) rather than threads.

``num_actors=2`` (or ``"max"``) spreads each population over EvoTorch's Ray actors; each
actor then runs its share as one batch.
"""

from __future__ import annotations

from typing import Any

import torch
from evotorch import Problem, SolutionBatch
from torch import Tensor

from evolution.config import NEATConfig
from evolution.phenotype import SigmoidSpec, SpikingSpec, as_spec, make_controller, spec_name
from evolution.population import Genomes
from evolution.rollout import episode_starts, rollout
from evolution.task import Task

__all__ = ["FixedTopologyProblem"]

CONTROLLERS = ("snn", "sigmoid")


def _as_mask(mask: Any, config: NEATConfig) -> Tensor:
    N = config.num_nodes
    if not isinstance(mask, Tensor):
        try:
            mask = torch.as_tensor(mask)
        except (TypeError, ValueError, RuntimeError) as exc:
            raise ValueError(f"mask must be a [N, N] bool tensor, got {type(mask).__name__}") from exc
    if tuple(mask.shape) != (N, N):
        raise ValueError(f"mask must have shape [N, N] = ({N}, {N}) (config.num_nodes), got {tuple(mask.shape)}")
    if mask.dtype != torch.bool:
        if mask.is_floating_point() or mask.is_complex() or not bool(((mask == 0) | (mask == 1)).all()):
            raise ValueError(f"mask must be bool (or 0/1 integers), got {mask.dtype}")
        mask = mask.bool()
    return mask


class FixedTopologyProblem(Problem):
    """The non-Markov cart-pole as an EvoTorch problem over the weights of a fixed topology.

    Args:
        config: the NEAT layout (``tasks.studies.cartpole.controller_config``): node
            slots, weight and sigma bounds.
        mask: ``[N, N]`` bool, connection (i, j) from node i to node j is searched. Must
            reach every output and lead into no input or bias node.
        controller: ``"snn"`` (Qiu et al.'s spiking controller, searches ln sigma too; the default)
            or ``"sigmoid"`` (the sigmoid NEAT baseline, weights only): the controller with its
            spec's defaults; or leave it out and pass ``spec``, which decides.
        task: the ``evolution.task.Task`` to search on (e.g. ``tasks.cartpole.CartPoleTask.nonmarkov()``).
        starts: ``[S, ...]`` start states (as ``task.reset`` returns them); fitness is the mean
            over them (of the return or the steps survived, ``task.fitness``). Default:
            ``episodes`` starts from ``task.reset`` with a generator seeded by ``start_seed``.
        max_steps: episode length cap (default ``task.max_steps``).
        template: a ``[1, 1]`` Genomes whose other genes (disabled ones, nodes) and sigma
            the decoded genomes keep; ``from_genome`` sets it. Default: the mask's genes
            only, weights 0, sigma ``config.sigma_init_mean``.
        init_radius: ``initial_bounds`` are ``initial_solution() +- init_radius`` (used by
            searchers given no ``center_init``, and by ``problem.generate_batch``).
        spec: the controller's ``SpikingSpec`` or ``SigmoidSpec`` (default: ``controller``'s defaults).
        dtype, device: of the solutions and of the evaluation.
        **problem_kwargs: passed to ``evotorch.Problem`` (``seed``, ``num_actors``,
            ``num_subbatches``, ``subbatch_size``, ...).
    """

    def __init__(self, config: NEATConfig, mask: Any, *, task: Task, controller: str | None = None,
                 starts: Tensor | None = None, episodes: int = 1, start_seed: int = 0, max_steps: int | None = None,
                 template: Genomes | None = None, init_radius: float = 1.0,
                 spec: SpikingSpec | SigmoidSpec | None = None, dtype: torch.dtype = torch.float32,
                 device: str | torch.device = "cpu", **problem_kwargs) -> None:
        if not isinstance(config, NEATConfig):
            raise ValueError(f"config must be a NEATConfig, got {type(config).__name__}")
        if controller is not None and controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
        spec = as_spec(controller if spec is None else spec, task)
        if controller is not None and spec_name(spec) != controller:
            raise ValueError(f"controller {controller!r} disagrees with spec {type(spec).__name__}: pass one of them")
        controller = spec_name(spec)
        if not isinstance(task, Task):
            raise ValueError(f"task must be an evolution.task.Task, got {type(task).__name__}")
        task.validate()
        max_steps = task.max_steps if max_steps is None else max_steps
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps must be an integer >= 1, got {max_steps!r}")
        if not (isinstance(init_radius, (int, float)) and init_radius > 0):
            raise ValueError(f"init_radius must be a positive number, got {init_radius!r}")
        mask = _as_mask(mask, config)
        if bool(mask[:, : config.first_output].any()):
            bad = torch.nonzero(mask[:, : config.first_output]).tolist()
            raise ValueError(f"mask has connections into input or bias nodes (from, to): {bad[:5]}")
        for out in range(config.first_output, config.first_hidden):
            if not bool(mask[:, out].any()):
                raise ValueError(f"mask has no connection into output node {out}: the controller's output "
                                 "would not depend on its weights")
        self.config, self.controller, self.task, self.spec = config, controller, task, spec
        self.max_steps = max_steps
        device = torch.device(device)
        if starts is None:
            starts = episode_starts(task, episodes, start_seed, device=device, dtype=dtype)
        if not isinstance(starts, Tensor) or starts.dim() < 1 or starts.shape[0] < 1:
            raise ValueError(f"starts must be a [S, ...] tensor of S >= 1 start states, got "
                             f"{tuple(starts.shape) if isinstance(starts, Tensor) else type(starts).__name__}")
        if starts.is_floating_point() and not bool(torch.isfinite(starts).all()):
            raise ValueError("starts holds NaN or inf")
        self.starts = starts.to(device=device, dtype=dtype if starts.is_floating_point() else starts.dtype)
        self.connections = torch.nonzero(mask).to(device)  # [C, 2], row-major (from, to)
        self._mask = mask.to(device)
        self._template = self._make_template(template, config, mask, dtype, device)
        self._x0 = self._encode(self._template)
        problem_kwargs.setdefault("eval_dtype", torch.float64)  # a mean of step counts, exactly
        super().__init__("max", solution_length=int(self._x0.shape[0]),
                         initial_bounds=((self._x0 - init_radius).tolist(), (self._x0 + init_radius).tolist()),
                         dtype=dtype, device=device, **problem_kwargs)

    # --- construction --------------------------------------------------------------------
    @classmethod
    def from_genome(cls, genomes: Genomes, config: NEATConfig, run: int = 0, index: int = 0,
                    **kwargs) -> FixedTopologyProblem:
        """The problem over the enabled genes of genome ``[run, index]``; it keeps that genome's
        disabled genes and nodes, and ``initial_solution()`` is that genome."""
        if not isinstance(genomes, Genomes):
            raise ValueError(f"genomes must be a Genomes, got {type(genomes).__name__}")
        if not (0 <= run < genomes.num_runs and 0 <= index < genomes.pop_size):
            raise ValueError(f"genome [{run}, {index}] is outside the population's shape "
                             f"[{genomes.num_runs}, {genomes.pop_size}]")
        one = genomes.select_runs([run]).gather(torch.tensor([[index]], device=genomes.device))
        kwargs.setdefault("dtype", genomes.weight.dtype)
        kwargs.setdefault("device", genomes.device)
        return cls(config, one.enabled[0, 0], template=one, **kwargs)

    @staticmethod
    def _make_template(template: Genomes | None, config: NEATConfig, mask: Tensor, dtype: torch.dtype,
                       device: torch.device) -> Genomes:
        N = config.num_nodes
        if template is None:
            node = torch.zeros(N, dtype=torch.bool)
            node[: config.first_hidden] = True
            node |= mask.any(0) | mask.any(1)
            sigma = torch.tensor(float(config.sigma_init_mean)).clamp(config.sigma_min_value, config.sigma_max_value)
            template = Genomes(weight=torch.zeros(1, 1, N, N), conn=mask[None, None].clone(),
                               enabled=mask[None, None].clone(), node=node[None, None],
                               sigma=sigma.reshape(1, 1))
        if not isinstance(template, Genomes) or template.num_runs != 1 or template.pop_size != 1:
            raise ValueError("template must be a [1, 1] Genomes")
        if template.num_nodes != N:
            raise ValueError(f"template has {template.num_nodes} node slots, config.num_nodes is {N}")
        t = template.to(device)
        enabled = t.enabled | mask.to(device)
        return Genomes(weight=t.weight.to(dtype), conn=t.conn | enabled, enabled=enabled, node=t.node,
                       sigma=t.sigma.to(dtype))

    # --- the solution vector -------------------------------------------------------------
    @property
    def num_weights(self) -> int:
        """``C``, the searched connections."""
        return int(self.connections.shape[0])

    def _encode(self, g: Genomes) -> Tensor:
        i, j = self.connections.unbind(-1)
        w = g.weight[0, 0, i, j]
        if self.controller == "snn":
            w = torch.cat([w, g.sigma[0, 0].log().reshape(1)])
        return w

    def initial_solution(self) -> Tensor:
        """The template's solution vector (a champion's own weights and ln sigma): use it as
        a Gaussian searcher's ``center_init``."""
        return self._x0.clone()

    def _check_values(self, values: Any, name: str) -> Tensor:
        if hasattr(values, "values") and not isinstance(values, Tensor):  # evotorch Solution / SolutionBatch
            values = values.values
        values = torch.as_tensor(values)
        shape = tuple(values.shape)
        if type(values) is not Tensor:  # EvoTorch's ReadOnlyTensor would make every derived tensor read-only
            values = values.as_subclass(Tensor)
        if values.dim() == 1:
            values = values.unsqueeze(0)
        D = self.solution_length
        if values.dim() != 2 or values.shape[-1] != D:
            what = "ln sigma" if self.controller == "snn" else "no sigma"
            raise ValueError(f"{name} must have length {D} ({self.num_weights} weights, {what}), "
                             f"got shape {shape}")
        if not bool(torch.isfinite(values).all()):
            raise ValueError(f"{name} holds NaN or inf")
        return values.to(device=self._template.device, dtype=self._template.weight.dtype)

    def decode(self, values: Any, repeats: int = 1) -> Genomes:
        """``[E, D]`` solution values -> a ``[E, repeats]`` population (each solution
        ``repeats`` times, as expanded views), weights and sigma clamped to the config's bounds."""
        if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
            raise ValueError(f"repeats must be a positive int, got {repeats!r}")
        values = self._check_values(values, "solution")
        cfg, t = self.config, self._template
        E, N = values.shape[0], cfg.num_nodes
        i, j = self.connections.unbind(-1)
        weight = t.weight[0, 0].expand(E, N, N).clone()
        weight[:, i, j] = values[:, : self.num_weights].clamp(cfg.weight_min_value, cfg.weight_max_value)
        if self.controller == "snn":
            sigma = values[:, -1].exp().clamp(cfg.sigma_min_value, cfg.sigma_max_value)
        else:
            sigma = t.sigma[0, 0].expand(E)
        return Genomes(weight=weight.unsqueeze(1).expand(E, repeats, N, N),
                       conn=t.conn[0, 0].expand(E, repeats, N, N), enabled=t.enabled[0, 0].expand(E, repeats, N, N),
                       node=t.node[0, 0].expand(E, repeats, N), sigma=sigma.unsqueeze(1).expand(E, repeats))

    def to_genomes(self, solution: Any) -> Genomes:
        """A solution (tensor ``[D]``, an EvoTorch ``Solution``) -> a ``[1, 1]`` Genomes, or
        several (``[E, D]``, a ``SolutionBatch``) -> ``[1, E]``; ready for ``save_genome``."""
        g = self.decode(solution, 1)
        return Genomes(**{k: v.transpose(0, 1).contiguous() for k, v in g.tensors().items()})

    # --- evaluation ----------------------------------------------------------------------
    def fitness(self, values: Any) -> Tensor:
        """Mean fitness over ``starts`` (the task's return or steps survived), ``[E]`` float64,
        for ``[E, D]`` solution values: one rollout of ``E`` controllers x ``S`` episodes."""
        genomes = self.decode(values, 1)
        controller = make_controller(genomes, self.config, self.task, self.spec)
        result = rollout(self.task, controller, episodes=self.starts.shape[0], starts=self.starts,
                         max_steps=self.max_steps)
        return result.fitness(self.task.fitness).mean(-1)

    def seed(self, seed: int | None = None) -> None:
        """Alias of ``manual_seed``: EvoTorch 0.6.1's Ray actors call ``problem.seed(...)`` when the
        problem has its own generator (``seed=`` given), and ``Problem`` has no such method."""
        self.manual_seed(seed)

    def _evaluate_batch(self, batch: SolutionBatch) -> None:
        batch.set_evals(self.fitness(batch.values).to(batch.values.device))
