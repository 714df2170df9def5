"""The CLI under misuse: one line per user error (exit 2), a lock per --out, Ctrl-C (exit 130)
with the command that resumes, resumable evolve and xor, reports marked complete, clean folders."""

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from evolution.checkpoint import load_checkpoint_dict
from tasks.studies.cli import CommandError, main
from tasks.studies.lock import LOCK_NAME, OutputLock

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
XOR = ["xor", "--runs", "2", "--generations", "3", "--quiet"]


def _one_line_error(capsys, argv, match):
    """``main(argv)`` fails with exit status 2 and one stderr line matching ``match``."""
    with pytest.raises(CommandError) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert match in err and match in str(exc.value), err
    return err


@pytest.mark.parametrize("argv, match", [
    (["xor", "--out", ""], "--out is empty"),
    (["evolve", "--out", " "], "--out is empty"),
    pytest.param(["xor", "--device", "cuda:0" if not torch.cuda.is_available() else "cuda:99"],
                 "is not available here", id="absent-gpu"),
    (["xor", "--device", "meta"], "not meta"),
    (["evolve", "--device", "nope"], "--device 'nope' is not a device name"),
    (["reproduce", "table2", "--threads", "100000"], "--threads 100000 is more than 4 per CPU"),
    (["xor", "--threads", "100000"], "use at most"),
    (["xor", "--seed", str(2**63 - 1), "--runs", "2"], "reaches seed 9223372036854775808"),
    (["evolve", "--seed", str(2**63)], "seeds must be below 2**63"),
    (["reproduce", "table2", "--seed", str(2**64), "--runs", "1"], "seeds must be below 2**63"),
    (["xor", "--runs", "100000000000"], "--runs 100000000000 needs about"),
    (["reproduce", "table1", "--runs", "100000000", "--controllers", "snn"], "use fewer --runs"),
    (["reproduce", "dpv", "--fitness-starts", "4"], "fitness_starts must be 1 for dpv (a fitness over several "
                                                      "starts only for dpnv), got 4"),
    (["reproduce", "table2", "--champion-test", "species"], "'species' only for dpnv"),
    (["reproduce", "dpv", "--fitness", "damping-both-poles"], "'damping-both-poles' only for dpnv"),
    (["reproduce", "dpv", "--min-general", "300"], "min_general: only dpnv count generalisation starts"),
    (["reproduce", "dpnv", "--min-general", "626"], "min_general must be an int of generalisation starts in 0..625"),
])
def test_bad_options_are_one_line_before_any_work(argv, match, capsys, tmp_path):
    out = tmp_path / "out"
    if "--out" not in argv:
        argv = [*argv, "--out", str(out)]
    _one_line_error(capsys, argv, match)
    assert not out.exists() or not any(out.iterdir())  # nothing evolved, nothing written


def test_an_out_that_cannot_be_a_folder_is_named(capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    _one_line_error(capsys, [*XOR, "--out", str(afile)], "is a file, not a folder")
    _one_line_error(capsys, [*XOR, "--out", str(afile / "sub")], "cannot be created")
    _one_line_error(capsys, ["figures", "--out", str(afile)], "is a file, not a folder")


def test_parse_errors_are_one_line_with_status_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["xor", "--runs", "-3"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--runs" in err and "--help" in err


def test_resume_with_nothing_to_resume_says_so(capsys, tmp_path):
    _one_line_error(capsys, [*XOR, "--out", str(tmp_path / "x"), "--resume"], "no checkpoint")
    _one_line_error(capsys, ["evolve", "--out", str(tmp_path / "e"), "--resume"], "no checkpoint")
    _one_line_error(capsys, ["reproduce", "table2", "--runs", "1", "--out", str(tmp_path / "r"), "--resume"],
                    "holds no checkpoint of this reproduction")


def test_a_damaged_checkpoint_is_one_line_naming_it(capsys, tmp_path):
    out = tmp_path / "x"
    out.mkdir()
    (out / "xor.ckpt").write_bytes(b"SNN-NEAT-CKPT\n" + b"\0" * 40)
    err = _one_line_error(capsys, [*XOR, "--out", str(out), "--resume"], "corrupted")
    assert "xor.ckpt" in err and "Traceback" not in err


def _hold_lock(out: Path) -> subprocess.Popen:
    code = ("import sys, time; from tasks.studies.lock import OutputLock; OutputLock(sys.argv[1], 'snn-neat other').acquire(); "
            "print('held', flush=True); time.sleep(120)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(out)], env=ENV, stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_command_into_a_busy_out_is_refused(capsys, tmp_path):
    out = tmp_path / "busy"
    holder = _hold_lock(out)
    try:
        for argv in (XOR, ["evolve", "--generations", "2"],
                     ["reproduce", "table2", "--runs", "2", "--generations", "2", "--quiet"]):
            err = _one_line_error(capsys, [*argv, "--out", str(out)], "is in use by another snn-neat command")
            assert f"PID {holder.pid}" in err and "snn-neat other" in err
            assert [p.name for p in out.iterdir()] == [LOCK_NAME]  # nothing of ours was written
    finally:
        holder.kill()
        holder.wait()


def test_a_stale_lock_of_a_dead_process_is_taken_over_and_stale_temp_files_go(tmp_path):
    out = tmp_path / "x"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / LOCK_NAME).write_text(json.dumps({"pid": dead.pid, "host": os.uname().nodename, "started": 0}))
    temps = [out / ".xor.ckpt.a1b2c3d4.tmp", out / "champions" / ".snn_seed1.json.zz_9yx8w.tmp",
             out / ".fig.png.abcdefgh.png", out / "shards" / "snn-0" / ".snn.ckpt.q1w2e3r4.tmp"]
    kept = [out / ".keep.me", out / "mine" / ".notes.txt.abcdefgh.tmp"]  # not a temp name; not our folder
    for t in temps + kept:
        t.parent.mkdir(parents=True, exist_ok=True)
        t.write_bytes(b"partial")
    assert main([*XOR, "--out", str(out)]) == 0
    assert not any(t.exists() for t in temps) and all(k.exists() for k in kept)
    assert (out / "summary.md").exists() and not (out / LOCK_NAME).exists()


def test_the_lock_is_released_and_refused_within_one_process_too(tmp_path):
    with OutputLock(tmp_path, "a"):
        with pytest.raises(Exception, match="in use"):
            OutputLock(tmp_path, "b").acquire()
    with OutputLock(tmp_path, "c"):
        pass


def test_files_honour_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        assert main([*XOR, "--out", str(tmp_path / "x")]) == 0
    finally:
        os.umask(old)
    for name in ("runs.csv", "summary.json", "summary.md", "xor.ckpt"):
        assert stat.S_IMODE((tmp_path / "x" / name).stat().st_mode) == 0o640, name


def test_ctrl_c_exits_130_naming_the_resume_command_and_resume_equals_uninterrupted(tmp_path, capsys, monkeypatch):
    import tasks.studies.xor as xor_mod

    argv = ["xor", "--runs", "3", "--generations", "6", "--seed", "7", "--quiet", "--checkpoint-every", "1"]
    assert main([*argv, "--out", str(tmp_path / "ref")]) == 0
    real, calls = xor_mod.xor_fitness, []

    def interrupted(g, cfg):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(g, cfg)

    monkeypatch.setattr(xor_mod, "xor_fitness", interrupted)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--out", str(tmp_path / "cut")])
    assert exc.value.code == 130
    err = capsys.readouterr().err.strip()
    assert err.endswith(f"continue with: snn-neat {' '.join(argv)} --out {tmp_path / 'cut'} --resume"), err
    assert "Traceback" not in err and not (tmp_path / "cut" / "summary.md").exists()
    assert load_checkpoint_dict(tmp_path / "cut" / "xor.ckpt")["neat"]["generation"] == 2
    monkeypatch.setattr(xor_mod, "xor_fitness", real)
    assert main([*argv, "--out", str(tmp_path / "cut"), "--resume"]) == 0
    assert (tmp_path / "cut" / "runs.csv").read_bytes() == (tmp_path / "ref" / "runs.csv").read_bytes()
    # a budget it has passed (it ran 2 generations or more) cannot be resumed to
    with pytest.raises(CommandError, match="generations=6, this call asks for generations=1"):
        main(["xor", "--runs", "3", "--generations", "1", "--seed", "7", "--quiet", "--out", str(tmp_path / "cut"),
              "--resume", "--checkpoint-every", "1"])
    with pytest.raises(CommandError, match="exists: pass --resume"):
        main([*argv, "--out", str(tmp_path / "cut")])


def test_an_xor_checkpoint_from_before_a_config_field_existed_resumes(tmp_path, capsys):
    from evolution.checkpoint import atomic_torch_save

    argv = ["xor", "--runs", "2", "--generations", "4", "--seed", "3", "--quiet", "--checkpoint-every", "1"]
    assert main([*argv, "--out", str(tmp_path / "ref")]) == 0
    assert main([*argv, "--out", str(tmp_path / "old")]) == 0
    path = tmp_path / "old" / "xor.ckpt"
    old = load_checkpoint_dict(path)
    for part in (old["identity"]["config"], old["neat"]["config"]):  # as written before initial_hidden existed
        del part["initial_hidden"]
    atomic_torch_save(old, path)
    assert main([*argv, "--out", str(tmp_path / "old"), "--resume"]) == 0
    assert (tmp_path / "old" / "runs.csv").read_bytes() == (tmp_path / "ref" / "runs.csv").read_bytes()
    old["identity"]["config"]["pop_size"] += 1  # a field that did change still refuses
    atomic_torch_save(old, path)
    with pytest.raises(CommandError, match="cannot resume .* it was written with config="):
        main([*argv, "--out", str(tmp_path / "old"), "--resume"])


def test_an_interrupted_xor_report_does_not_look_complete(tmp_path, monkeypatch):
    import tasks.studies.xor as xor_mod

    summary = xor_mod.run_xor([1, 2], generations=2, progress=False)
    out = tmp_path / "x"
    xor_mod.write_xor_report(summary, out)
    real = xor_mod.atomic_write_bytes

    def full_disk(path, data):
        if Path(path).name == "summary.json":
            raise OSError(28, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(xor_mod, "atomic_write_bytes", full_disk)
    with pytest.raises(OSError):
        xor_mod.write_xor_report(summary, out)
    assert not (out / "summary.md").exists()  # the earlier report's marker went first


def _wait_for_checkpoint(path: Path, generation: int, proc: subprocess.Popen) -> None:
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        try:
            if load_checkpoint_dict(path)["neat"]["generation"] >= generation:
                return
        except Exception:  # noqa: BLE001, S110 - not written yet
            pass
        time.sleep(0.05)
    raise AssertionError(f"{path} never reached generation {generation} (process ended: {proc.poll()})")


def test_evolve_survives_sigint_then_sigkill_and_resumes_to_the_same_bits(tmp_path):
    # A run long enough to interrupt twice: NEAT-SNN on Table I (its survivors balance 100,000-step
    # episodes; sigmoid NEAT on Table II now ends within a second, before a signal can reach it).
    args = ["evolve", "--controller", "snn", "--task", "markov", "--generations", "7", "--seed", "3", "--threads", "1"]
    assert main([*args, "--out", str(tmp_path / "ref")]) == 0
    cut = tmp_path / "cut"
    # Ctrl-C as in a terminal: a suite started in the background (`cmd &`) inherits SIGINT ignored,
    # and Python then never raises KeyboardInterrupt, so the child gets the default back.
    proc = subprocess.Popen([sys.executable, "-m", "tasks.studies.cli", *args, "--out", str(cut)], env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    _wait_for_checkpoint(cut / "evolve.ckpt", 1, proc)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 130
    last = proc.stderr.read().strip().splitlines()[-1]
    assert "Traceback" not in last and last.endswith(f"--out {cut} --resume"), last
    proc = subprocess.Popen([sys.executable, "-m", "tasks.studies.cli", *args, "--out", str(cut), "--resume"], env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _wait_for_checkpoint(cut / "evolve.ckpt", 2, proc)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (cut / "champion.json").exists()
    assert main([*args, "--out", str(cut), "--resume"]) == 0
    for name in ("statistics.csv", "champion.json"):
        assert (cut / name).read_bytes() == (tmp_path / "ref" / name).read_bytes(), name


def test_a_crafted_command_checkpoint_is_one_line_naming_it(capsys, tmp_path):
    from evolution.checkpoint import atomic_torch_save

    out = tmp_path / "x"
    assert main([*XOR, "--out", str(out)]) == 0
    good = load_checkpoint_dict(out / "xor.ckpt")
    for key, value, match in (("wall_s", float("nan"), "wall_s is nan"),
                              ("statistics", [1, 2], "statistics is not a list of rows"),
                              ("neat", [], "not a checkpoint of `snn-neat xor`"),
                              ("identity", {"command": "xor"}, "it was written with seeds=None")):
        atomic_torch_save({**good, key: value}, out / "xor.ckpt")
        capsys.readouterr()
        _one_line_error(capsys, [*XOR, "--out", str(out), "--resume"], match)


@pytest.mark.parametrize("every, interval_s, saved", [(2, 0.0, [2, 4, 5]), (None, 0.0, [1, 2, 3, 4, 5]),
                                                      (None, 3600.0, [5])])
def test_run_checkpoint_writes_every_n_generations_or_by_time_and_at_the_end(tmp_path, monkeypatch, every,
                                                                             interval_s, saved):
    from evolution.neat import NEAT
    from tasks.studies.resumable import RunCheckpoint
    from tests.evolution.helpers import small_config

    neat = NEAT(small_config(), seeds=[0])
    ckpt = neat.add_reporter(RunCheckpoint(tmp_path / "c.ckpt", {"command": "test"}, 5, every=every,
                                           interval_s=interval_s))
    written = []
    real = ckpt.save
    monkeypatch.setattr(ckpt, "save", lambda status: written.append(status.generations_done) or real(status))
    neat.run(lambda g: torch.zeros(1, 6, dtype=torch.float64), 5)
    assert written == saved


def test_ray_missing_is_one_line(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ModuleNotFoundError
    _one_line_error(capsys, ["reproduce", "table2", "--runs", "1", "--ray", "auto", "--out", str(tmp_path)],
                    "--ray needs Ray")


@pytest.mark.parametrize("error", [MemoryError(), RuntimeError("[enforce fail] DefaultCPUAllocator: can't allocate "
                                                                "memory: you tried to allocate 8000000000000 bytes")])
def test_running_out_of_memory_is_one_line(error, capsys, tmp_path, monkeypatch):
    import tasks.studies.xor as xor_mod

    def exhausted(*args, **kwargs):
        raise error

    monkeypatch.setattr(xor_mod, "run_xor", exhausted)
    _one_line_error(capsys, [*XOR, "--out", str(tmp_path)], "out of memory: use fewer --runs")


@pytest.mark.parametrize("table, controller", [("dpnv", "snn"), ("dpnv", "sigmoid"), ("dpv", "sigmoid"),
                                               ("table1", "snn"), ("table2", "sigmoid")])
def test_the_memory_check_sizes_the_configs_the_study_evolves(table, controller):
    """The check reads the config run_controller evolves: the default setup's population (DPNV's best:
    NEAT-SNN 100, sigmoid NEAT 300), not Table II's 150."""
    from tasks.studies.cli import _configs, build_parser
    from tasks.studies.reproduce import study_config

    args = build_parser().parse_args(["reproduce", table, "--controllers", controller])
    [config] = _configs(args)
    assert config == study_config(table, controller)
    assert config.pop_size == {("dpnv", "snn"): 100, ("dpnv", "sigmoid"): 300}.get((table, controller), 150)
    push_pull = 2 if (table, controller) == ("dpnv", "snn") else 1  # NEAT-SNN's best DPNV setup: two inputs a variable
    assert config.num_inputs == {"dpnv": 3, "dpv": 6, "table1": 4, "table2": 2}[table] * push_pull
