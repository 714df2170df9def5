"""The ``snn-neat`` command."""

from __future__ import annotations

import argparse
import faulthandler
import os
import shlex
import sys
import time
from dataclasses import fields
from pathlib import Path

# OpenMP threads (torch's and the C kernels') sleep at a barrier instead of spinning: on a busy
# machine a spinning thread burns the core its partner is waiting for (Table II with two competing
# busy processes: 67 s wall, 57 CPU-s spinning; 56 s, 40 CPU-s passive). Set before torch loads
# its OpenMP runtime (nothing above imports torch); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# The studies, their GA presets, codings and champion tests: the registry imports no torch, so
# --help needs none.
from tasks.studies.registry import GA_CHOICES, STUDIES, StudyOptions  # noqa: E402


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _cmd_figures(args: argparse.Namespace) -> int:
    _check_out(args.out)
    from evolution.checkpoint import file_mode
    from snn_torch.plots import save_neuron_figures

    start = time.perf_counter()
    paths = save_neuron_figures(args.out, dt_ms=args.dt_ms)
    for path in paths:
        os.chmod(path, file_mode())  # written through mkstemp (0o600): give them the umask's mode
        print(f"wrote {path}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _int_at_least(minimum: int):
    """An argparse type: an integer >= ``minimum``."""
    what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


class CommandError(SystemExit):
    """A user error: ``main`` has printed it as one line; the exit status is 2. ``str()`` is the line."""

    def __init__(self, line: str) -> None:
        super().__init__(2)
        self.line = line

    def __str__(self) -> str:
        return self.line


class UsageError(Exception):
    """Bad input that the options' parsers could not see (the message names the option)."""


SEED_LIMIT = 2**63  # evolution.rng keys a run by a 64-bit signed hash of its seed


def _check_out(out: str) -> Path:
    """``--out`` as a folder this process can write (created if missing), before any work."""
    if not out.strip():
        raise UsageError("--out is empty: name an output folder, e.g. --out results/run1")
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise UsageError(f"--out {out!r} is a file, not a folder: choose a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out {out!r} cannot be created ({exc.strerror}): choose a folder you can write") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UsageError(f"--out {out!r} is not writable: choose a folder you can write")
    return path


def _check_device(text: str) -> str:
    """``--device`` as a torch device that exists here (cpu, cuda, cuda:N)."""
    import torch

    try:
        device = torch.device(text)
    except (RuntimeError, ValueError):
        raise UsageError(f"--device {text!r} is not a device name: use cpu or cuda (cuda:N)") from None
    if device.type not in ("cpu", "cuda"):
        raise UsageError(f"--device {text!r}: snn-neat runs on cpu or cuda (cuda:N), not {device.type}")
    try:
        torch.empty(1, device=device)
    except Exception as exc:  # noqa: BLE001 - torch raises AssertionError (no CUDA build), RuntimeError, ...
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UsageError(f"--device {text!r} is not available here ({reason}): use --device cpu") from None
    return text


def _check_threads(threads: int | None) -> None:
    """``--threads``: at most 4 per CPU (OpenMP crashes creating 100,000), then set."""
    if threads is None:
        return
    limit = 4 * (os.cpu_count() or 1)
    if threads > limit:
        raise UsageError(f"--threads {threads} is more than 4 per CPU of this machine ({os.cpu_count()} CPUs): "
                         f"use at most {limit}")
    import torch

    torch.set_num_threads(threads)


def _check_seeds(first: int, runs: int = 1) -> list[int]:
    last = first + runs - 1
    if last >= SEED_LIMIT:
        what = f"--seed {first}" + (f" with --runs {runs} reaches seed {last}" if runs > 1 else "")
        raise UsageError(f"{what}; seeds must be below 2**63 = {SEED_LIMIT}: choose a smaller --seed")
    return list(range(first, last + 1))


def _clean(out: str) -> None:
    """Remove the temp files killed writes left where the commands write: ``OUT``, its
    ``champions/``, ``shards/`` and each shard's folder (call it holding ``OUT``'s lock)."""
    from evolution.checkpoint import clean_stale_temps

    root = Path(out)
    clean_stale_temps(root, root / "champions", root / "shards", *(p for p in root.glob("shards/*") if p.is_dir()))


def _check_memory(runs: int, configs: list) -> None:
    """Refuse a ``--runs`` whose populations alone cannot fit in this machine's memory (a typo
    such as --runs 100000000 would otherwise spend minutes before failing)."""
    # weight (float32) + conn + enabled bytes per gene slot, times 3: parents, children, a checkpoint's
    # copy; the controllers of a reproduction evolve one after another
    need = max(runs * c.pop_size * c.num_nodes**2 * 6 * 3 for c in configs)
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # no sysconf: no check
        return
    if need > total:
        raise UsageError(f"--runs {runs} needs about {need / 1e9:,.0f} GB for its populations alone, more than this "
                         f"machine's {total / 1e9:,.0f} GB: use fewer --runs")


def _study_options(args: argparse.Namespace) -> StudyOptions:
    """The ``StudyOptions`` a ``reproduce`` command line gives (None: the setup's)."""
    return StudyOptions(**{f.name: getattr(args, f.name) for f in fields(StudyOptions)})


def _configs(args: argparse.Namespace) -> list:
    """The NEAT configs a command will evolve (for the memory check)."""
    if args.command == "xor":
        from tasks.studies.xor import XOR_CONFIG

        return [XOR_CONFIG]
    if args.command == "reproduce":  # options the study does not offer stop here, before any work
        s, options = STUDIES[args.table], _study_options(args)
        return [s.config(c, options) for c in args.controllers]
    table = "table1" if args.task == "markov" else "table2"
    return [STUDIES[table].config(args.controller, self_loops=args.self_loops, ga=args.ga)]


def _prepare(args: argparse.Namespace) -> list[int]:
    """Check every option that needs this machine, before any work; returns the seeds."""
    _check_memory(getattr(args, "runs", 1), _configs(args))
    seeds = _check_seeds(args.seed, getattr(args, "runs", 1))
    _check_device(args.device)
    _check_threads(args.threads)
    _check_out(args.out)
    return seeds


def _cmd_xor(args: argparse.Namespace) -> int:
    seeds = _prepare(args)
    from tasks.studies.lock import OutputLock
    from tasks.studies.xor import run_xor, write_xor_report

    with OutputLock(args.out, _command_line(args)):
        _clean(args.out)
        summary = run_xor(seeds, generations=args.generations, device=args.device, out=args.out, resume=args.resume,
                          checkpoint_every=args.checkpoint_every, progress=not args.quiet)
        for path in write_xor_report(summary, args.out):
            print(f"wrote {path}")
    t = summary.table()
    print(f"{t['runs']} runs (seeds {seeds[0]}..{seeds[-1]}): {t['failures']} failures, mean "
          f"{t['mean_generations']:.2f} generations, median {t['median_generations']}, mean hidden nodes "
          f"{t['mean_hidden_nodes']:.2f}; {t['wall_s']:.1f} s")
    return 0


PAPER_TASKS = ("nonmarkov", "markov")
# options of one mode of `evolve` only: (dest, option, given?)
_CARTPOLE_ONLY = (("task", "--task", lambda v: v is not None), ("self_loops", "--self-loops", bool),
                  ("ga", "--ga", lambda v: v is not None), ("verbose", "--verbose", bool),
                  ("report_every", "--report-every", lambda v: v is not None))
_ENV_ONLY = (("runs", "--runs", lambda v: v is not None), ("episodes", "--episodes", lambda v: v is not None),
             ("pop_size", "--pop-size", lambda v: v is not None), ("threshold", "--threshold", lambda v: v is not None),
             ("ray", "--ray", lambda v: v is not None))


def _evolve_mode(args: argparse.Namespace) -> None:
    """Which ``evolve`` this is: ENV (``args.env``) or the paper's cart-pole (``args.env`` None,
    ``args.task`` set); options of the other mode, or both budgets, are a ``UsageError``."""
    if args.env in PAPER_TASKS:  # `snn-neat evolve markov` is `snn-neat evolve --task markov`
        if args.task is not None and args.task != args.env:
            raise UsageError(f"ENV {args.env} and --task {args.task} disagree: give one of them")
        args.task, args.env = args.env, None
    if args.generations is not None and args.episodes is not None:
        raise UsageError(f"--generations {args.generations} and --episodes {args.episodes} are two budgets: "
                         "give one of them")
    if args.env is None:
        for dest, option, given in _ENV_ONLY:
            if given(getattr(args, dest)):
                raise UsageError(f"{option} needs ENV (a gymnasium id or module:Class); the paper's cart-pole "
                                 f"(--task) takes no {option}: name ENV, or drop {option}")
        args.task = args.task or "nonmarkov"
        args.runs, args.ga = 1, args.ga or "tuned"
        args.generations = args.generations or 100
        args.report_every = args.report_every or 1
        args.checkpoint_every = args.checkpoint_every or 1
        return
    for dest, option, given in _CARTPOLE_ONLY:
        if given(getattr(args, dest)):
            raise UsageError(f"{option} is for the paper's cart-pole (no ENV); with ENV {args.env} the run uses the "
                             f"library's defaults: drop {option}")
    args.runs = args.runs or 1


def _evolve_out(env: str | None) -> str:
    """``evolve``'s default ``--out``: results/evolve, or results/evolve-ENV (ENV made a folder name)."""
    if env is None or env in PAPER_TASKS:
        return "results/evolve"
    return "results/evolve-" + "".join(c if c.isalnum() or c in "-_." else "_" for c in env)


def _cmd_evolve(args: argparse.Namespace) -> int:
    _evolve_mode(args)
    if args.env is not None:
        return _cmd_evolve_env(args)
    _prepare(args)
    from tasks.studies.evolve import run_evolve, write_evolve_report
    from tasks.studies.lock import OutputLock

    out = args.out
    with OutputLock(out, _command_line(args)):
        _clean(out)
        r = run_evolve(args.controller, args.task, args.seed, args.generations, out, resume=args.resume,
                       self_loops=args.self_loops, ga=args.ga, device=args.device, verbose=args.verbose,
                       report_every=args.report_every, checkpoint_every=args.checkpoint_every,
                       progress=not args.quiet)
        write_evolve_report(r, out)
    solved = r.result.solved_generation[0].item()
    print(f"{args.controller} seed {args.seed}: best fitness {r.result.best_fitness[0].item():.0f} steps; "
          + (f"solved at generation {solved}" if solved > 0 else f"not solved in {args.generations} generations")
          + f"; wrote {out}/statistics.csv and {out}/champion.json")
    return 0


def _cmd_evolve_env(args: argparse.Namespace) -> int:
    """``snn-neat evolve ENV`` (``tasks.studies.evolve_env``)."""
    seeds = _check_seeds(args.seed, args.runs)
    _check_device(args.device)
    from tasks.studies.evolve_env import EvolvePlan, build, has_local_run, has_shards, run_plan
    from tasks.studies.evolve_env_report import summary_table, write_report
    from tasks.studies.lock import OutputLock

    plan = EvolvePlan(env=args.env, controller=args.controller, seeds=tuple(seeds), generations=args.generations,
                      episodes=args.episodes, pop_size=args.pop_size, threshold=args.threshold, device=args.device,
                      checkpoint_every=args.checkpoint_every)
    built = build(plan)  # ENV and the budget checked before any work
    _check_memory(len(seeds), [built.config])
    _check_threads(args.threads)
    _check_out(args.out)
    command = _command_line(args)
    with OutputLock(args.out, command):
        _clean(args.out)
        if args.resume and not (has_local_run(args.out) or has_shards(args.out)):
            raise UsageError(f"--resume: --out {args.out!r} holds no checkpoint of `snn-neat evolve` (evolve.ckpt or "
                             "shards/evolve.json): run without --resume to start")
        runs = run_plan(plan, args.out, resume=args.resume, ray_address=args.ray, progress=not args.quiet,
                        built=built)
        for path in write_report(runs, args.out, command):
            if path.parent.name != "champions":
                print(f"wrote {path}")
    print(f"wrote {len(runs.records)} champion genome(s) to {Path(args.out) / 'champions'}")
    print(summary_table(runs), end="")
    return 0


def _controllers(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in ("snn", "sigmoid")]
    if not names or bad or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of snn,sigmoid, got {text!r}")
    return names


def _reproduce_checkpoints(args: argparse.Namespace) -> list[Path]:
    """The checkpoints (or Ray shard manifests) of this reproduction already in ``--out``."""
    from tasks.studies.distributed import has_shards

    out = Path(args.out)
    return [out / f"{c}.ckpt" if (out / f"{c}.ckpt").exists() else out / "shards" / f"{c}.json"
            for c in args.controllers if (out / f"{c}.ckpt").exists() or has_shards(out, c)]


def _cmd_reproduce(args: argparse.Namespace) -> int:
    seeds = _prepare(args)
    from tasks.studies.distributed import has_shards, run_controller_sharded, run_controllers_on_ray
    from tasks.studies.lock import OutputLock
    from tasks.studies.reproduce import run_controller, write_report

    command = _command_line(args)
    results = {}
    s, options = STUDIES[args.table], _study_options(args)
    budget = {c: s.generations(s.config(c, options), generations=args.generations, evaluations=args.evaluations)
              for c in args.controllers}
    common = dict(options=options, resume=args.resume, checkpoint_every=args.checkpoint_every, device=args.device,
                  progress=not args.quiet)
    with OutputLock(args.out, command):
        _clean(args.out)
        if args.resume and not _reproduce_checkpoints(args):
            raise UsageError(f"--resume: --out {args.out!r} holds no checkpoint of this reproduction "
                             f"({', '.join(c + '.ckpt' for c in args.controllers)}): run without --resume to start")
        if args.ray is not None:
            results = run_controllers_on_ray(args.table, args.controllers, seeds, budget, args.out,
                                             address=args.ray, shards=args.shards, **common)
        else:
            for c in args.controllers:
                if args.shards is not None or has_shards(args.out, c):  # the shard layout of a (Ray) run
                    results[c] = run_controller_sharded(args.table, c, seeds, budget[c], args.out,
                                                        shards=args.shards, **common)
                else:
                    results[c] = run_controller(args.table, c, seeds, budget[c], args.out, **common)
        for path in write_report(results, args.table, args.out, command=command,
                                 generalization=not args.no_generalization):
            if path.suffix != ".json" or path.parent.name != "champions":
                print(f"wrote {path}")
    print((Path(args.out) / f"{args.table}.md").read_text())
    return 0


def _command_line(args: argparse.Namespace, *, resume: bool = False) -> str:
    """The command as typed (``args.argv``), with ``--resume`` added if asked."""
    argv = list(args.argv)
    named = args.command == "reproduce" or (args.command == "evolve" and getattr(args, "env", None) is not None)
    if named and "--out" not in argv and not any(a.startswith("--out=") for a in argv):
        argv += ["--out", args.out]  # the default folder, named: a resume must find it
    if resume and "--resume" not in argv:
        argv.append("--resume")
    return "snn-neat " + shlex.join(argv)


def _resume_hint(args: argparse.Namespace) -> str:
    """What to type after an interruption: the resume command where a checkpoint exists."""
    if args.command == "figures":
        return "run it again to redo the figures"
    out = Path(args.out)
    if args.command == "reproduce":
        kept = bool(_reproduce_checkpoints(args))
    elif args.command == "evolve":
        kept = (out / "evolve.ckpt").exists() or (out / "shards" / "evolve.json").exists()
    else:
        kept = (out / ("xor.ckpt" if args.command == "xor" else "evolve.ckpt")).exists()
    if kept:
        return f"the last checkpoint is kept; continue with: {_command_line(args, resume=True)}"
    return f"no checkpoint was written yet; start again with: {_command_line(args)}".replace(" --resume", "")


class _Parser(argparse.ArgumentParser):
    """argparse's errors as one line (usage is a --help away), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _add_run_options(p: argparse.ArgumentParser, *, every: int | None) -> None:
    """--resume, --checkpoint-every and --threads, as ``reproduce`` has them."""
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out (--generations may change: a budget it has not passed)")
    p.add_argument("--checkpoint-every", type=_positive_int, default=every,
                   help="generations between checkpoints (default: "
                        + ("every 30 s, and at the end)" if every is None else f"{every})"))
    p.add_argument("--threads", type=_positive_int, default=None, help="torch threads (default: torch's)")


def _add_study_options(p: argparse.ArgumentParser) -> None:
    """A flag per ``StudyOptions`` field (``--setup``, ``--ga``, ...), each None unless given, so the
    setup's value holds where the command line says nothing."""
    for f in fields(StudyOptions):
        meta, flag = f.metadata, "--" + f.name.replace("_", "-")
        if meta["kind"] == "flag":
            p.add_argument(flag, action="store_true", default=None, help=meta["help"])
            continue
        kw: dict = {"metavar": meta["metavar"]} if meta["metavar"] else {}
        if meta["offered"]:
            kw["choices"] = tuple(dict.fromkeys(c for s in STUDIES.values() for c in getattr(s, meta["offered"])))
        kind = {"str": str, "int": int, "count": _positive_int}[meta["kind"]]
        p.add_argument(flag, type=kind, default=None, help=meta["help"], **kw)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="snn-neat", description="Evolving spiking neural networks in PyTorch.",
        epilog="Exit status: 0 done, 2 a user error (one line on stderr saying what to change), 130 interrupted "
               "(Ctrl-C; the line names the command that resumes).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    fig = sub.add_parser(
        "figures", help="regenerate the paper's neuron figures (Fig. 1 and Fig. 2) as PNG",
        description="Regenerate Qiu et al.'s Fig. 1 (voltage response to a square current) and "
                    "Fig. 2 (f-I curve, I from 0 to 200) as PNG files.")
    fig.add_argument("--out", default="figures", help="output folder (default: figures)")
    fig.add_argument("--dt-ms", type=_positive_float, default=0.02,
                     help="integration step in ms (default: 0.02)")
    fig.set_defaults(func=_cmd_figures)

    xor = sub.add_parser(
        "xor", help="NEAT sanity check: evolve XOR over many seeded runs (Stanley & Miikkulainen 2002)",
        description="Evolve XOR with sigmoid tensor NEAT, one run per seed (seeds SEED..SEED+RUNS-1), all "
                    "runs in one batch; write runs.csv, summary.json and summary.md.")
    xor.add_argument("--runs", type=_positive_int, default=100, help="number of runs (default: 100)")
    xor.add_argument("--seed", type=_non_negative_int, default=0, help="first seed (default: 0)")
    xor.add_argument("--generations", type=_positive_int, default=100, help="budget per run (default: 100)")
    xor.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    xor.add_argument("--out", default="results/xor", help="output folder (default: results/xor)")
    _add_run_options(xor, every=None)
    xor.add_argument("--quiet", action="store_true", help="no progress bar")
    xor.set_defaults(func=_cmd_xor)

    evo = sub.add_parser(
        "evolve", help="evolve a controller on any plant (a gymnasium id or your own Task), or on the paper's "
                       "cart-pole",
        description="Evolve NEAT-SNN or sigmoid NEAT on ENV with the library's defaults (what task_config and "
                    "TaskFitness make for the task): RUNS seeded runs (seeds SEED..SEED+RUNS-1) in one batch, each "
                    "stopping when a genome that reached the threshold in training also reaches it on 32 held-out "
                    "episodes; each run's champion is then tested on 100 fresh episodes. Writes results.json (every "
                    "setting, per run: generations, training episodes, CPU and wall seconds to the threshold, the test, "
                    "the learning curve), learning_curve.png and champions/seedS.json, and prints a table. "
                    "Without ENV (or with ENV nonmarkov or markov): one controller on a cart-pole task of Qiu et al., "
                    "nonmarkov (Table II: x and theta only, tau 10 ms, start at 3 degrees, success at 5000 steps) or "
                    "markov (Table I: all four state variables, bang-bang force, tau 20 ms, success at 100,000 "
                    "steps); writes the per-generation statistics and the champion genome.")
    evo.add_argument("env", nargs="?", default=None, metavar="ENV",
                     help="a gymnasium id (CartPole-v1, Acrobot-v1, MountainCar-v0, MountainCarContinuous-v0 and "
                          "Pendulum-v1 run as batched torch ports; any other through gymnasium; threshold: its "
                          "reward_threshold) or module:Class, your evolution.Task subclass (made with no arguments, "
                          "found from the current folder too; threshold: its optional reward_threshold attribute)")
    evo.add_argument("--controller", choices=["snn", "sigmoid"], default="snn", help="controller (default: snn)")
    evo.add_argument("--seed", type=_non_negative_int, default=0, help="first run's seed (default: 0)")
    evo.add_argument("--runs", type=_positive_int, default=None,
                     help="ENV only: runs, seeds SEED..SEED+RUNS-1, evolved as one batch (default: 1)")
    evo.add_argument("--generations", type=_positive_int, default=None,
                     help="budget per run in generations (default: 200 with ENV, 100 for the cart-pole)")
    evo.add_argument("--episodes", type=_positive_int, default=None, metavar="N",
                     help="ENV only, instead of --generations: budget per run in training episodes (genomes x "
                          "episodes each, per generation; a run stops before the generation that would spend more)")
    evo.add_argument("--pop-size", type=_int_at_least(2), default=None,
                     help="ENV only: genomes per run (default: the library's)")
    evo.add_argument("--threshold", type=_finite_float, default=None, metavar="X",
                     help="ENV only: the score that counts as solved (default: ENV's reward_threshold; none: every "
                          "run spends its budget)")
    evo.add_argument("--out", default=None, help="output folder (default: results/evolve-ENV, or results/evolve)")
    evo.add_argument("--resume", action="store_true",
                     help="continue from the checkpoint in --out (--generations or --episodes may grow)")
    evo.add_argument("--ray", default=None, metavar="auto|HOST:PORT",
                     help="ENV only: run the seeds as Ray tasks on this cluster, one shard per cluster CPU ('auto': "
                          "the one `ray start` started here); OUT must be on a filesystem all its nodes share, and "
                          "a module:Class importable on every node")
    evo.add_argument("--quiet", action="store_true", help="no progress bar")
    evo.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    evo.add_argument("--checkpoint-every", type=_positive_int, default=None,
                     help="generations between checkpoints (default: every 30 s and at the end with ENV; 1 for the "
                          "cart-pole)")
    evo.add_argument("--threads", type=_positive_int, default=None, help="torch threads (default: torch's)")
    cart = evo.add_argument_group("the paper's cart-pole (no ENV)")
    cart.add_argument("--task", choices=list(PAPER_TASKS), default=None,
                      help="task (default: nonmarkov, Table II; markov: Table I)")
    cart.add_argument("--self-loops", action="store_true",
                      help="start with an output self-connection (neat-python's full start)")
    cart.add_argument("--ga", choices=GA_CHOICES, default=None,
                      help="GA settings (default: tuned, the controller's pick for the task; or a preset: "
                           + ", ".join(GA_CHOICES[1:]) + ")")
    cart.add_argument("--verbose", action="store_true", help="a line per generation instead of a progress bar")
    cart.add_argument("--report-every", type=_positive_int, default=None, help="with --verbose: every N generations")
    evo.set_defaults(func=_cmd_evolve)

    rep = sub.add_parser(
        "reproduce", help="reproduce the paper's Table I or II, or run the double-pole study (NEAT-SNN vs sigmoid "
                          "NEAT, many seeded runs)",
        description="Reproduce Qiu et al.'s Table I (Markov cart-pole) or Table II (non-Markov), or run the "
                    "double-pole study beyond the paper (dpv: with velocities, dpnv: without, as NEAT 2002): RUNS "
                    "seeded runs (seeds SEED..SEED+RUNS-1) of each controller, all runs of a controller in one "
                    "batch, with a checkpoint after every generation. Tables: TABLE.md/.csv (best, worst, median, "
                    "mean with failures as GENERATIONS+1, failure rate, Mann-Whitney U p-value), runs.csv, "
                    "summary.json, fig8_best_fitness.png, trajectory and topology plots and every champion genome. "
                    "Double pole: VARIANT.md (evaluations to solve beside the published figures, generalisation, "
                    "champion sizes, memory ablation), runs.csv, summary.json, plots and every champion genome.")
    rep.add_argument("table", choices=list(STUDIES), help="which table to reproduce: the paper's table1 or table2, "
                     "or beyond the paper, double-pole balancing with (dpv) or without (dpnv) velocities")
    rep.add_argument("--runs", type=_positive_int, default=60, help="runs per controller (default: 60, the paper's)")
    rep.add_argument("--seed", type=_non_negative_int, default=0, help="first seed (default: 0)")
    budget = rep.add_mutually_exclusive_group()
    budget.add_argument("--generations", type=_positive_int, default=None,
                        help="budget per run in generations (default: the study's: 100 for the tables)")
    budget.add_argument("--evaluations", type=_positive_int, default=None, metavar="N",
                        help="budget per run in evaluations (genomes evaluated, as NEAT counts them; each controller "
                             "runs N // its population generations; default for dpv 15,000 and dpnv 100,000, NEAT C++ "
                             "1.2.1's 100 generations of 150 and of 1000)")
    rep.add_argument("--controllers", type=_controllers, default=["snn", "sigmoid"],
                     help="comma-separated subset of snn,sigmoid (default: both)")
    _add_study_options(rep)
    rep.add_argument("--out", default=None, help="output folder (default: results/TABLE)")
    rep.add_argument("--resume", action="store_true", help="continue from the checkpoints in --out (--generations may change the budget of the unsolved runs, to one they have not passed)")
    rep.add_argument("--checkpoint-every", type=_positive_int, default=1, help="generations between checkpoints")
    rep.add_argument("--device", default="cpu", help="torch device (default: cpu)")
    rep.add_argument("--threads", type=_positive_int, default=None, help="torch threads (default: torch's)")
    rep.add_argument("--no-generalization", action="store_true",
                     help="skip the 625-start-state generalisation test of every champion")
    rep.add_argument("--quiet", action="store_true", help="no progress bar")
    rep.add_argument("--ray", default=None, metavar="auto|HOST:PORT",
                     help="run the seeds as Ray tasks on this cluster ('auto': the one `ray start` started on this "
                          "machine); OUT must be on a filesystem all its nodes share (default: run locally)")
    rep.add_argument("--shards", type=_positive_int, default=None,
                     help="split each controller's runs into N shards, one Ray task each (default with --ray: one "
                          "per cluster CPU); a resumed run keeps its split")
    rep.set_defaults(func=_cmd_reproduce)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run a command. User errors print one line and raise ``CommandError`` (exit status 2);
    Ctrl-C prints how to resume and exits with 130."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.argv = argv
    if not faulthandler.is_enabled():  # a crash in C (a task's native step) names the Python frame
        faulthandler.enable()
    if getattr(args, "command", None) == "reproduce" and args.out is None:
        args.out = f"results/{args.table}"
    if getattr(args, "command", None) == "evolve" and args.out is None:
        args.out = _evolve_out(args.env)
    prog = f"snn-neat {args.command}"
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print(f"\n{prog}: interrupted; {_resume_hint(args)}", file=sys.stderr, flush=True)
        raise SystemExit(130) from None
    except CommandError:
        raise
    except Exception as exc:
        message = _user_error(exc)
        if message is None:
            raise
        line = f"{prog}: error: {message}"
        print(line, file=sys.stderr, flush=True)
        raise CommandError(line) from None


def _user_error(exc: Exception) -> str | None:
    """The one-line message for an error the user can fix, or None for a bug (its traceback shows)."""
    from evolution.checkpoint import CheckpointError
    from evolution.config import ConfigError
    from evolution.task import TaskError
    from tasks.studies.env_task import EnvError
    from tasks.studies.lock import LockError
    from tasks.studies.registry import ReproduceError

    if isinstance(exc, (UsageError, ReproduceError, CheckpointError, ConfigError, LockError, EnvError, TaskError)):
        return " ".join(str(exc).split("\n"))
    import torch

    oom = getattr(torch, "OutOfMemoryError", MemoryError)  # CUDA's (torch >= 2.5)
    if isinstance(exc, (MemoryError, oom)) or (isinstance(exc, RuntimeError) and "can't allocate memory" in str(exc)):
        return "out of memory: use fewer --runs, or free memory (on a GPU: use a larger one or --device cpu)"
    if isinstance(exc, ModuleNotFoundError) and (exc.name or "").split(".")[0] == "ray":
        return "--ray needs Ray, which is not installed here: pip install 'ray[default]', or leave --ray out"
    if isinstance(exc, OSError):  # a full disk, a folder made read-only meanwhile, ...
        where = f" {exc.filename}" if exc.filename else ""
        return f"cannot write{where}: {exc.strerror or exc}; free space or choose another --out"
    return None


if __name__ == "__main__":
    sys.exit(main())
