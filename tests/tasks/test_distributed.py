"""Sharded reproduction on a real local Ray cluster (``ray start --head`` in a subprocess).

The clusters are stopped by killing their own process group (``ray start`` runs in a new
session), never ``ray stop``, which would stop every Ray cluster on the machine.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import torch

pytest.importorskip("ray")

from tasks.studies.distributed import (  # noqa: E402
    has_shards,
    merge_runs,
    run_controller_on_ray,
    run_controller_sharded,
    shard_seeds,
)
from tasks.studies.reproduce import ReproduceError, run_controller  # noqa: E402
from tasks.studies.results import ControllerRuns  # noqa: E402

RAY = str(Path(sys.executable).parent / "ray")
TASK, CONTROLLER, SEEDS, GENERATIONS = "table2", "sigmoid", [0, 1, 2, 3], 6
LONG = 12  # generations, so a shard is still running when the test interrupts it


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """A one-node Ray cluster with 2 CPUs, in its own process group."""

    def __init__(self, log: Path):
        self.port = _free_port()
        self.address = f"127.0.0.1:{self.port}"
        with open(log, "w") as f:
            proc = subprocess.Popen([RAY, "start", "--head", "--node-ip-address=127.0.0.1", f"--port={self.port}",
                                     "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats"],
                                    stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
            rc = proc.wait(timeout=120)
        self.pgid = proc.pid  # the daemons (GCS, raylet, ...) stay in this process group
        if rc != 0:
            self.stop()
            pytest.fail(f"ray start failed ({rc}): {log.read_text()[-2000:]}")

    def processes(self) -> list[int]:
        """The cluster's processes: its process group and their descendants (the raylet
        starts its workers in process groups of their own)."""
        parent, group = {}, {}
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                try:
                    fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                except OSError:
                    continue
                parent[int(entry.name)], group[int(entry.name)] = int(fields[1]), int(fields[2])
        found = {pid for pid, g in group.items() if g == self.pgid}
        while True:
            more = {pid for pid, ppid in parent.items() if ppid in found} - found
            if not more:
                return sorted(found)
            found |= more

    def stop(self) -> None:
        """Kill every process of the cluster at once, as if its machine went down."""
        for pid in self.processes():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    c = Cluster(tmp_path_factory.mktemp("ray") / "ray_start.log")
    yield c
    c.stop()


@pytest.fixture(autouse=True)
def _no_ray_left_connected():
    import ray

    yield
    if ray.is_initialized():
        ray.shutdown()


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> ControllerRuns:
    """The plain local run: all seeds in one batch."""
    return run_controller(TASK, CONTROLLER, SEEDS, GENERATIONS, tmp_path_factory.mktemp("local"), progress=False)


@pytest.fixture(scope="module")
def long_reference(tmp_path_factory) -> ControllerRuns:
    r = run_controller(TASK, CONTROLLER, SEEDS, LONG, tmp_path_factory.mktemp("local"), progress=False)
    assert min(len(r.history), *(g for g in r.solved_generation if g > 0)) > 3  # still running when interrupted
    return r


def _assert_same(a: ControllerRuns, b: ControllerRuns) -> None:
    assert a.seeds == b.seeds
    assert a.solved_generation == b.solved_generation
    assert a.best_fitness == b.best_fitness
    assert torch.equal(a.history, b.history)
    for name, t in a.champions.tensors().items():
        assert torch.equal(t, getattr(b.champions, name)), name


def _wait_for(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def _pid(folder: Path) -> int | None:
    try:
        return json.loads((folder / "worker.json").read_text())["pid"]
    except (OSError, ValueError, KeyError):
        return None


def test_shard_seeds():
    assert shard_seeds(range(5), 2) == [[0, 1, 2], [3, 4]]
    assert shard_seeds([7, 3, 9], 8) == [[7], [3], [9]]
    assert shard_seeds([1, 2], 1) == [[1, 2]]
    with pytest.raises(ReproduceError, match="--shards"):
        shard_seeds([1, 2], 0)


def test_merged_shards_equal_one_batch(reference, tmp_path):
    parts = [run_controller(TASK, CONTROLLER, s, GENERATIONS, tmp_path / str(k), progress=False)
             for k, s in enumerate(shard_seeds(SEEDS, 3))]
    merged = merge_runs(parts)
    _assert_same(merged, reference)
    assert merged.history.shape == (GENERATIONS, len(SEEDS))
    assert merged.wall_s == pytest.approx(sum(p.wall_s for p in parts))
    for key in ("cpu_s", "solve_test_cpu_s"):  # the report's cost row: every shard's CPU seconds
        assert merged.extra[key] == pytest.approx(sum(p.extra[key] for p in parts))
    assert merged.extra["cpu_s"] > 0
    del parts[1].extra["cpu_s"]  # a shard that does not know its CPU time: the sum is unknown, not short
    assert "cpu_s" not in merge_runs(parts).extra


def test_ray_equals_local(cluster, reference, tmp_path, capsys):
    out = tmp_path / "out"
    r = run_controller_on_ray(TASK, CONTROLLER, SEEDS, GENERATIONS, out, address=cluster.address)
    _assert_same(r, reference)
    assert r.extra["shards"] == 2  # one per cluster CPU
    err = capsys.readouterr().err
    assert "sigmoid shard 1/2 (seeds 0..1) finished" in err and "[2/2 shards]" in err
    assert has_shards(out, CONTROLLER)
    # finished: a second call needs --resume, and then only reads the checkpoints
    with pytest.raises(ReproduceError, match="--resume"):
        run_controller_sharded(TASK, CONTROLLER, SEEDS, GENERATIONS, out)
    _assert_same(run_controller_sharded(TASK, CONTROLLER, SEEDS, GENERATIONS, out, resume=True, progress=False),
                 reference)
    with pytest.raises(ReproduceError, match="--shards 3"):
        run_controller_sharded(TASK, CONTROLLER, SEEDS, GENERATIONS, out, resume=True, shards=3)


def test_killed_worker_is_retried(cluster, long_reference, tmp_path):
    out = tmp_path / "out"
    folder = out / "shards" / f"{CONTROLLER}-0"
    killed = {}

    def kill_after_first_checkpoint():
        _wait_for(lambda: (folder / f"{CONTROLLER}.ckpt").exists(), 120, "the first checkpoint of shard 0")
        killed["pid"] = _pid(folder)
        os.kill(killed["pid"], signal.SIGKILL)

    killer = threading.Thread(target=kill_after_first_checkpoint, daemon=True)
    killer.start()
    r = run_controller_on_ray(TASK, CONTROLLER, SEEDS, LONG, out, address=cluster.address, shards=2,
                              progress=False)
    killer.join(timeout=5)
    assert "pid" in killed
    assert _pid(folder) != killed["pid"]  # the retried task ran in another worker
    _assert_same(r, long_reference)
    assert r.extra["complete"]


def test_bad_address_is_a_clear_error(tmp_path):
    address = f"127.0.0.1:{_free_port()}"  # nothing listens there
    start = time.perf_counter()
    with pytest.raises(ReproduceError, match=f"--ray '{address}': cannot reach a Ray cluster"):
        run_controller_on_ray(TASK, CONTROLLER, SEEDS, GENERATIONS, tmp_path, address=address)
    assert time.perf_counter() - start < 20
    with pytest.raises(ReproduceError, match="--ray 'no-port'"):
        run_controller_on_ray(TASK, CONTROLLER, SEEDS, GENERATIONS, tmp_path, address="no-port")

    from tasks.studies.cli import main

    with pytest.raises(SystemExit, match=f"snn-neat reproduce: error: --ray '{address}'"):
        main(["reproduce", "table2", "--runs", "2", "--controllers", "sigmoid", "--out", str(tmp_path / "cli"),
              "--ray", address, "--quiet"])


def test_cluster_lost_mid_run_then_local_resume(long_reference, tmp_path):
    """The driver runs in a subprocess (the CLI): after losing the GCS, Ray's client state
    in that process is unusable, which must not leak into this one."""
    out = tmp_path / "out"
    doomed = Cluster(tmp_path / "ray_start.log")
    try:
        cmd = [sys.executable, "-m", "tasks.studies.cli", "reproduce", TASK, "--runs", str(len(SEEDS)), "--generations",
               str(LONG), "--controllers", CONTROLLER, "--out", str(out), "--ray", doomed.address,
               "--shards", "4", "--no-generalization", "--quiet"]
        with open(tmp_path / "driver.log", "w") as log:
            driver = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
            try:
                # 4 shards on 2 CPUs: once a third shard has checkpointed, one has finished
                # (Ray does not start the shards in index order)
                def started():
                    return len(list(out.glob(f"shards/{CONTROLLER}-*/{CONTROLLER}.ckpt")))

                _wait_for(lambda: started() >= 3 or driver.poll() is not None, 120, "a third shard")
                doomed.stop()
                lost_at = time.monotonic()
                rc = driver.wait(timeout=90)
                exit_s = time.monotonic() - lost_at
            finally:
                if driver.poll() is None:
                    driver.kill()
        text = (tmp_path / "driver.log").read_text()
        assert rc != 0, text[-3000:]
        assert exit_s < 30, exit_s
    finally:
        doomed.stop()
    assert f"snn-neat reproduce: error: --ray '{doomed.address}': lost the Ray cluster" in text, text[-3000:]
    assert "--resume" in text
    finished = text.split("Finished shards", 1)[1].split(". Run the same command", 1)[0]
    done = [k for k in range(4) if f"{CONTROLLER} shard {k + 1}/4 (seeds {k})" in finished]
    assert 1 <= len(done) < 4, finished
    for k in done:  # a finished shard's results stay on disk
        assert (out / "shards" / f"{CONTROLLER}-{k}" / f"{CONTROLLER}.ckpt").exists()

    from tasks.studies.cli import main

    main(["reproduce", TASK, "--runs", str(len(SEEDS)), "--generations", str(LONG), "--controllers",
          CONTROLLER, "--out", str(out), "--resume", "--no-generalization", "--quiet"])
    rows = (out / "runs.csv").read_text().splitlines()[1:]
    assert [int(row.split(",")[3]) for row in rows] == long_reference.solved_generation
    assert [float(row.split(",")[5]) for row in rows] == long_reference.best_fitness
    _assert_same(run_controller_sharded(TASK, CONTROLLER, SEEDS, LONG, out, resume=True, progress=False),
                 long_reference)
