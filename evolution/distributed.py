"""A population's fitness evaluated in shards on a Ray cluster.

For populations too large for one machine's evaluation budget: the ``[R, P]`` population is
split along its genome axis into ``shards`` slices, each evaluated by the user's
``fitness_fn`` in a Ray task (one CPU, or one GPU, each), and the ``[R, P_k]`` results are
concatenated. Selection and reproduction stay in the driver (they are a small part of a
generation). Whole independent runs are better sent as whole tasks:
``tasks.studies.distributed`` does that for ``snn-neat reproduce``.

    import ray
    from evolution import NEAT
    from evolution.distributed import RayFitness

    ray.init(address="auto")                      # or "HOST:PORT" of `ray start --head`
    neat = NEAT(config, seeds=range(60))
    neat.run(RayFitness(fitness_fn, shards=32), generations=100, fitness_target=5000)

The result equals ``fitness_fn(genomes)`` when ``fitness_fn`` scores every genome by itself
(a pure function of that genome, as every fitness in this package is): a fitness that draws
from a global random stream, or ranks genomes against each other, would differ.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from evolution.population import Genomes

__all__ = ["RayFitness", "split_genomes"]


def split_genomes(genomes: Genomes, shards: int) -> list[Genomes]:
    """``genomes`` split along the genome axis into ``min(shards, P)`` contiguous slices."""
    if shards < 1:
        raise ValueError(f"shards must be >= 1, got {shards}")
    parts = min(shards, genomes.pop_size)
    sliced = {name: torch.tensor_split(t, parts, dim=1) for name, t in genomes.tensors().items()}
    return [Genomes(**{name: pieces[k] for name, pieces in sliced.items()}) for k in range(parts)]


def _evaluate_shard(fitness_fn: Callable[[Genomes], Tensor], genomes: Genomes) -> Tensor:
    return fitness_fn(genomes)


class RayFitness:
    """``fitness_fn`` evaluated as ``shards`` Ray tasks per call; ``ray.init`` must have run.

    Args:
        fitness_fn: ``Genomes[R, P] -> Tensor[R, P]``, picklable (closures are fine: Ray
            uses cloudpickle); it is put in Ray's object store once, not sent per call.
        shards: tasks per call (at most ``P``); about the cluster's CPUs (or GPUs).
        num_cpus, num_gpus: resources of each task.
        max_retries: times Ray reruns a task whose worker died.
    """

    def __init__(self, fitness_fn: Callable[[Genomes], Tensor], shards: int, *, num_cpus: float = 1,
                 num_gpus: float = 0, max_retries: int = 3) -> None:
        import ray

        if shards < 1:
            raise ValueError(f"RayFitness: shards must be >= 1, got {shards}")
        if not ray.is_initialized():
            raise RuntimeError("RayFitness needs a Ray connection: call ray.init(address='auto' or 'HOST:PORT') "
                               "first (or ray.init() for a local one)")
        self.shards = shards
        self._fn_ref = ray.put(fitness_fn)
        self._remote = ray.remote(_evaluate_shard).options(num_cpus=num_cpus, num_gpus=num_gpus,
                                                            max_retries=max_retries)

    def __call__(self, genomes: Genomes) -> Tensor:
        import ray

        device = genomes.device
        parts = split_genomes(Genomes(**{k: v.cpu() for k, v in genomes.tensors().items()}), self.shards)
        refs = [self._remote.remote(self._fn_ref, part) for part in parts]
        results = ray.get(refs)
        for part, fit in zip(parts, results, strict=True):
            if not isinstance(fit, Tensor) or tuple(fit.shape) != (part.num_runs, part.pop_size):
                shape = tuple(fit.shape) if isinstance(fit, Tensor) else type(fit).__name__
                raise ValueError(f"RayFitness: fitness_fn returned {shape} for a shard of "
                                 f"{(part.num_runs, part.pop_size)} genomes; expected a tensor of that shape")
        return torch.cat([f.cpu() for f in results], dim=1).to(device)
