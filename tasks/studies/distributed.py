"""A reproduction's independent NEAT runs, split into shards and run as Ray tasks.

A run's result does not depend on which other runs share its batch, so the seeds of one
controller can be split into shards (contiguous slices of the seed list), each shard evolved
by :func:`~tasks.studies.reproduce.run_controller` on its own, and the shard results
concatenated (:func:`merge_runs`): the merged result equals the one-batch local run.

Layout under ``OUT``::

    OUT/shards/<controller>.json      the manifest: the seeds and how they were split
    OUT/shards/<controller>-<k>/      shard k's folder: <controller>.ckpt (its checkpoint,
                                      written after every generation) and worker.json
                                      (host and pid of the process that last ran it)

Resume semantics: a shard task always continues from its checkpoint when it exists, so a
task that Ray retries after its worker died (``max_retries``) picks up from its last
generation. A finished shard's checkpoint stays on disk. If the cluster goes away mid-run,
:func:`run_controllers_on_ray` raises :class:`~tasks.studies.reproduce.ReproduceError`
naming the shards that finished; ``--resume`` (on Ray again, or locally: the local path
:func:`run_controller_sharded` follows the manifest when one exists) completes the rest and
gives the same results as an uninterrupted run. A resumed reproduction keeps the manifest's
split, whatever ``--shards`` says now.

On a multi-machine cluster ``OUT`` must be on a filesystem that every node sees at the same
path (NFS, a cluster filesystem): the shard tasks write their checkpoints there, and a
retried task on another node must find them. The package must be installed, at the same
version, in the Python environment of every node.
"""

from __future__ import annotations

import json
import os
import queue
import socket
import sys
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import torch

from evolution.checkpoint import atomic_write_bytes
from evolution.population import Genomes
from tasks.studies.registry import ReproduceError, StudyOptions
from tasks.studies.reproduce import run_controller
from tasks.studies.results import ControllerRuns

__all__ = ["Shard", "has_shards", "merge_runs", "run_controller_on_ray", "run_controller_sharded",
           "run_controllers_on_ray", "shard_layout", "shard_seeds"]

SHARDS = "shards"
LOST_AFTER_S = 3.0  # the cluster counts as gone when its GCS refuses connections this long


@dataclass(frozen=True)
class Shard:
    """Seeds ``seeds`` of ``controller``, checkpointed in ``folder``."""

    controller: str
    index: int
    seeds: list[int]
    folder: Path

    def describe(self, count: int) -> str:
        return f"{self.controller} shard {self.index + 1}/{count} (seeds {_span(self.seeds)})"


def _span(seeds: Sequence[int]) -> str:
    return f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])


def shard_seeds(seeds: Sequence[int], shards: int) -> list[list[int]]:
    """``seeds`` split into ``min(shards, len(seeds))`` contiguous slices, in order, sizes
    differing by at most one (the first ones larger)."""
    seeds = list(seeds)
    if shards < 1:
        raise ReproduceError(f"--shards must be >= 1, got {shards}")
    if not seeds:
        raise ReproduceError("no seeds to shard")
    shards = min(shards, len(seeds))
    size, extra = divmod(len(seeds), shards)
    out, start = [], 0
    for k in range(shards):
        stop = start + size + (k < extra)
        out.append(seeds[start:stop])
        start = stop
    return out


def merge_runs(parts: Sequence[ControllerRuns]) -> ControllerRuns:
    """The shards' results as one :class:`ControllerRuns`, runs in the order of ``parts``:
    per-run lists concatenated, ``history`` along its run axis, ``champions`` along the run
    axis, ``wall_s`` summed (CPU time over the shards, not elapsed time), the CPU seconds of
    evolution and of the solution test (``extra``) summed where every shard has them, ``config``
    kept."""
    if not parts:
        raise ReproduceError("no shard results to merge")
    first = parts[0]
    for p in parts[1:]:
        if p.controller != first.controller or p.generations != first.generations:
            raise ReproduceError(f"cannot merge shards of {first.controller!r} ({first.generations} generations) "
                                 f"and {p.controller!r} ({p.generations} generations)")
    champions = Genomes(**{name: torch.cat([getattr(p.champions, name) for p in parts])
                           for name in first.champions.tensors()})
    option_keys = ("setup", *StudyOptions.identity_defaults())
    extra = {"complete": all(p.extra.get("complete", True) for p in parts), "shards": len(parts),
             **{k: first.extra[k] for k in option_keys if k in first.extra},
             "solved_position": [q for p in parts for q in p.extra.get("solved_position", [-1] * len(p.seeds))]}
    for key in ("cpu_s", "solve_test_cpu_s"):  # a shard without the figure (an old checkpoint) leaves it unknown
        if all(key in p.extra for p in parts):
            extra[key] = sum(p.extra[key] for p in parts)
    return ControllerRuns(controller=first.controller, seeds=[s for p in parts for s in p.seeds],
                          generations=first.generations,
                          solved_generation=[g for p in parts for g in p.solved_generation],
                          best_fitness=[f for p in parts for f in p.best_fitness],
                          history=torch.cat([p.history for p in parts], dim=1), champions=champions,
                          config=first.config, wall_s=sum(p.wall_s for p in parts), extra=extra)


def _manifest(out: Path, controller: str) -> Path:
    return out / SHARDS / f"{controller}.json"


def has_shards(out: str | os.PathLike, controller: str) -> bool:
    """Whether ``out`` holds a sharded (Ray) reproduction of ``controller``."""
    return _manifest(Path(out), controller).exists()


def shard_layout(out: str | os.PathLike, controller: str, seeds: Sequence[int], shards: int | None, *,
                 resume: bool) -> list[Shard]:
    """The shards of ``controller`` under ``out``: the manifest's when one exists (which
    needs ``resume``), else ``shards`` new ones (the manifest is written)."""
    out, seeds = Path(out), list(seeds)
    path = _manifest(out, controller)
    local = out / f"{controller}.ckpt"
    if local.exists():
        raise ReproduceError(f"{local} is the checkpoint of a local (unsharded) run: "
                             + ("resume it without --ray" if resume else "choose another --out"))
    if path.exists():
        if not resume:
            raise ReproduceError(f"{path} exists: pass --resume to continue it, or choose another --out")
        saved = json.loads(path.read_text())
        if saved["seeds"] != seeds:
            raise ReproduceError(f"cannot resume {path}: it was written for seeds {_span(saved['seeds'])} "
                                 f"({len(saved['seeds'])} runs), this call asks for {_span(seeds)} ({len(seeds)} runs)")
        if shards is not None and shards != len(saved["shards"]):
            raise ReproduceError(f"cannot resume {path} with --shards {shards}: it was split into "
                                 f"{len(saved['shards'])} shards (leave --shards out to keep that)")
        split = saved["shards"]
    else:
        if shards is None:
            raise ReproduceError("the number of shards is needed for a new sharded reproduction")
        split = shard_seeds(seeds, shards)
        atomic_write_bytes(path, json.dumps({"controller": controller, "seeds": seeds, "shards": split},
                                            indent=1).encode())
    return [Shard(controller, k, s, out / SHARDS / f"{controller}-{k}") for k, s in enumerate(split)]


def _run_shard(task_name: str, shard: Shard, generations: int | None, *, options: StudyOptions | None = None,
               checkpoint_every: int = 1, device: str = "cpu", threads: int | None = None) -> ControllerRuns:
    """Run (or continue) one shard; what a Ray task runs, and what the local path runs."""
    if threads is not None:
        torch.set_num_threads(threads)
    shard.folder.mkdir(parents=True, exist_ok=True)
    info = {"host": socket.gethostname(), "pid": os.getpid(), "started": time.time()}
    atomic_write_bytes(shard.folder / "worker.json", json.dumps(info).encode())
    # Always resume: the manifest guards against overwriting a finished reproduction, and a
    # retried task must continue from the checkpoint its killed predecessor left.
    return run_controller(task_name, shard.controller, shard.seeds, generations, shard.folder, options=options,
                          resume=True, checkpoint_every=checkpoint_every, device=device, progress=False)


def _finished_line(task_name: str, shard: Shard, count: int, r: ControllerRuns, done: int, total: int) -> str:
    solved = sum(g > 0 for g in r.solved_generation)
    return (f"{task_name} {shard.describe(count)} finished: {solved}/{len(r.seeds)} solved, "
            f"{r.wall_s:.1f} s [{done}/{total} shards]")


def run_controller_sharded(task_name: str, controller: str, seeds: list[int], generations: int | None,
                           out: str | os.PathLike, *, options: StudyOptions | None = None, resume: bool = False,
                           shards: int | None = None, checkpoint_every: int = 1,
                           device: str | torch.device = "cpu", progress: bool = True,
                           **option_fields) -> ControllerRuns:
    """Like :func:`run_controller`, but shard by shard in this process, following the
    manifest in ``OUT/shards`` (how ``--resume`` without ``--ray`` completes a Ray run)."""
    options = replace(options or StudyOptions(), **option_fields)
    layout = shard_layout(out, controller, seeds, shards, resume=resume)
    parts = []
    for shard in layout:
        parts.append(_run_shard(task_name, shard, generations, options=options, checkpoint_every=checkpoint_every,
                                device=str(device)))
        if progress:
            print(_finished_line(task_name, shard, len(layout), parts[-1], len(parts), len(layout)), file=sys.stderr)
    return merge_runs(parts)


# --- Ray -----------------------------------------------------------------------------
def _resolve(address: str) -> tuple[str, int]:
    """``auto`` or ``HOST:PORT`` -> the GCS host and port, checked to accept connections (Ray
    itself retries an unreachable address for minutes)."""
    from ray._private import services

    try:
        resolved = services.canonicalize_bootstrap_address(address)
    except Exception as exc:  # Ray raises ValueError, ConnectionError, ... for bad addresses
        raise ReproduceError(f"--ray {address!r}: not a Ray cluster address ({exc}); "
                             "expected 'auto' or HOST:PORT of a running head node") from None
    if resolved is None:
        raise ReproduceError(f"--ray {address!r}: no running Ray cluster found on this machine; start one "
                             "with `ray start --head` or give its HOST:PORT")
    host, _, port = resolved.rpartition(":")
    try:
        port_no = int(port)
    except ValueError:
        raise ReproduceError(f"--ray {address!r}: expected HOST:PORT, got {resolved!r}") from None
    if not _reachable(host, port_no, timeout=5.0):
        raise ReproduceError(f"--ray {address!r}: cannot reach a Ray cluster at {host}:{port_no} (connection "
                             "refused or timed out); is `ray start --head` running there, and is the port open?")
    return host, port_no


def _reachable(host: str, port: int, timeout: float = 2.0) -> bool:
    try:
        with socket.create_connection((host.strip("[]"), port), timeout=timeout):
            return True
    except OSError:
        return False


def _connect(address: str) -> tuple[str, int]:
    import ray

    host, port = _resolve(address)
    if address != "auto":
        # `ray start` enables token authentication when ~/.ray/auth_token exists, but
        # ray.init(address=HOST:PORT) only sends the token when RAY_AUTH_MODE=token (it does
        # for address="auto"); follow Ray's own rule for "auto" here too.
        try:
            from ray._private.authentication.authentication_token_setup import (
                maybe_enable_token_auth_if_token_available,
            )

            maybe_enable_token_auth_if_token_available(warn_if_disabled=False)
        except ImportError:  # an older Ray without token authentication
            pass
    try:
        ray.init(address=address, log_to_driver=False, logging_level="ERROR", configure_logging=True)
    except Exception as exc:
        raise ReproduceError(f"--ray {address!r}: could not connect to the Ray cluster at {host}:{port} "
                             f"({type(exc).__name__}: {exc})") from None
    return host, port


def _abandon_ray() -> None:
    """After the cluster vanished: ray.shutdown() can block for minutes, so run it in a
    daemon thread, wait briefly, and keep the interpreter's exit from calling it again."""
    import atexit

    import ray

    t = threading.Thread(target=ray.shutdown, daemon=True)
    t.start()
    t.join(timeout=2.0)
    atexit.unregister(ray.shutdown)


def run_controllers_on_ray(task_name: str, controllers: Sequence[str], seeds: list[int],
                           generations: int | Mapping[str, int] | None, out: str | os.PathLike, *, address: str,
                           options: StudyOptions | None = None, shards: int | None = None, resume: bool = False,
                           checkpoint_every: int = 1, device: str = "cpu", progress: bool = True,
                           max_retries: int = 3, cpus_per_shard: int = 1, **option_fields) -> dict[str, ControllerRuns]:
    """Evolve ``seeds`` of every controller as Ray tasks on the cluster at ``address``
    (``"auto"`` or ``"HOST:PORT"``), one task per shard, all controllers' shards in flight
    together; returns each controller's merged results, equal to :func:`run_controller`'s.

    ``shards`` per controller defaults to the cluster's CPUs / ``cpus_per_shard`` (at most
    one per run). Each task runs with ``cpus_per_shard`` CPUs (and torch threads), one GPU
    when ``device`` is CUDA, and is retried ``max_retries`` times if its worker dies,
    continuing from its shard's checkpoint. Finished shards print a line to stderr.

    ``OUT`` must be on a filesystem shared by every node (see the module docstring). If
    the cluster is unreachable, or disappears mid-run, a :class:`ReproduceError` says so,
    names the finished shards, and ``--resume`` completes the rest later.
    """
    import ray
    import ray.exceptions

    out = Path(out)
    options = replace(options or StudyOptions(), **option_fields)
    budget = generations if isinstance(generations, Mapping) else {c: generations for c in controllers}
    if max_retries < 1:
        raise ReproduceError(f"max_retries must be >= 1, got {max_retries}")
    if ray.is_initialized():
        owned, gcs = False, None
        host_port = ray.get_runtime_context().gcs_address
        if host_port:
            h, _, p = host_port.rpartition(":")
            gcs = (h, int(p))
    else:
        gcs = _connect(address)
        owned = True
    lost = False
    try:
        if shards is None:
            cpus = int(ray.cluster_resources().get("CPU", 1))
            shards = max(1, cpus // cpus_per_shard)
        layouts = {c: shard_layout(out, c, seeds, shards, resume=resume) for c in controllers}
        gpus = 1 if str(device).startswith("cuda") else 0
        remote = ray.remote(_run_shard).options(num_cpus=cpus_per_shard, num_gpus=gpus, max_retries=max_retries,
                                                retry_exceptions=False)
        refs = {}
        for layout in layouts.values():
            for shard in layout:
                refs[remote.remote(task_name, shard, budget[shard.controller], options=options,
                                   checkpoint_every=checkpoint_every, device=str(device),
                                   threads=cpus_per_shard)] = shard
        total = len(refs)
        results: dict[tuple[str, int], ControllerRuns] = {}
        finished: list[Shard] = []

        def failure(why: str) -> ReproduceError:
            names = ", ".join(s.describe(len(layouts[s.controller])) for s in finished) or "none"
            return ReproduceError(f"--ray {address!r}: {why}. Finished shards (checkpoints kept under "
                                  f"{out / SHARDS}): {names}. Run the same command with --resume (with or without "
                                  "--ray) to complete the rest from their checkpoints.")

        try:
            for ref, value, exc in ray_results(refs, gcs):
                if exc is not None:
                    shard = refs.get(ref)
                    cause = getattr(exc, "cause", None)
                    if isinstance(cause, ReproduceError):
                        raise ReproduceError(f"{shard.describe(len(layouts[shard.controller]))}: {cause}") from None
                    where = f"{shard.describe(len(layouts[shard.controller]))} failed" if shard else "Ray failed"
                    raise failure(f"{where} ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") \
                        from None
                shard = refs[ref]
                results[(shard.controller, shard.index)] = value
                finished.append(shard)
                if progress:
                    print(_finished_line(task_name, shard, len(layouts[shard.controller]), value, len(results), total),
                          file=sys.stderr, flush=True)
        except RayClusterLost:
            lost = True
            raise failure(f"lost the Ray cluster at {gcs[0]}:{gcs[1]} mid-run") from None
        return {c: merge_runs([results[(c, s.index)] for s in layout]) for c, layout in layouts.items()}
    finally:
        if owned:
            if lost:
                _abandon_ray()
            else:
                ray.shutdown()


class RayClusterLost(Exception):
    """The Ray cluster's GCS was unreachable for ``LOST_AFTER_S`` seconds while tasks were pending."""


def ray_results(refs, gcs: tuple[str, int] | None) -> Iterator[tuple[object, object, Exception | None]]:
    """``(ref, value, exception)`` of each of the Ray tasks ``refs`` as it finishes (``exception``
    None where it returned ``value``), until all have; ``RayClusterLost`` once the cluster's GCS
    at ``gcs`` (host, port) has been unreachable for ``LOST_AFTER_S`` s. ``ray.wait``/``ray.get``
    block for minutes, whatever their timeout, once the GCS is gone: they run in a daemon thread,
    and the GCS is watched from here."""
    import ray

    inbox: queue.Queue = queue.Queue()

    def waiter() -> None:
        pending = list(refs)
        while pending:
            try:
                done, pending = ray.wait(pending, num_returns=1)
            except Exception as exc:  # noqa: BLE001 - reported by the caller
                inbox.put((None, None, exc))
                return
            for ref in done:
                try:
                    inbox.put((ref, ray.get(ref), None))
                except Exception as exc:  # noqa: BLE001
                    inbox.put((ref, None, exc))

    threading.Thread(target=waiter, daemon=True, name="snn-neat-ray-wait").start()
    received, unreachable_since = 0, None
    while received < len(refs):
        try:
            item = inbox.get(timeout=1.0)
        except queue.Empty:
            if gcs is not None and not _reachable(*gcs):
                unreachable_since = unreachable_since or time.monotonic()
                if time.monotonic() - unreachable_since > LOST_AFTER_S:
                    raise RayClusterLost from None
            else:
                unreachable_since = None
            continue
        received += 1
        yield item


def run_controller_on_ray(task_name: str, controller: str, seeds: list[int], generations: int,
                          out: str | os.PathLike, *, address: str, shards: int | None = None, resume: bool = False,
                          **kwargs) -> ControllerRuns:
    """One controller's runs on Ray; see :func:`run_controllers_on_ray`."""
    return run_controllers_on_ray(task_name, [controller], seeds, generations, out, address=address, shards=shards,
                                  resume=resume, **kwargs)[controller]
