"""``snn-neat evolve ENV``'s ENV: a gymnasium id or ``module:Class``, as a task and its threshold.

* A gymnasium id (``CartPole-v1``, ``Pendulum-v1``, ...): ``tasks.gym_adapter.GymTask(env_id)``,
  the batched torch port where there is one, gymnasium's own environment (the adapter)
  otherwise. Where gymnasium's observation space leaves a variable unbounded (CartPole-v1's
  velocities), a port's own bounds for it are used, and the adapter estimates them from
  random-action episodes (``tasks.gym_adapter.estimate_bounds``). The threshold is gymnasium's ``reward_threshold``
  (None where the environment has none, e.g. Pendulum-v1).
* ``module:Class`` (``Class`` a Python name, dots for nested classes): a subclass of
  ``evolution.Task`` in an importable module (the current folder is searched first, as
  ``python -m`` does), made with no arguments and validated; the threshold is its optional
  attribute ``reward_threshold`` (None: no threshold).

Anything that does not resolve is an ``EnvError`` saying what to change, in one line.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
from dataclasses import dataclass

from evolution.task import Task

__all__ = ["EnvError", "ResolvedEnv", "is_task_path", "resolve_env", "load_task", "gym_task"]


class EnvError(ValueError):
    """ENV names no task this command can run; the message says what to change."""


@dataclass(frozen=True)
class ResolvedEnv:
    """``task`` for ENV ``text``; ``kind``: "gymnasium" or "task"; ``threshold``: the score that
    counts as solved (None: none), and where it came from."""

    text: str
    kind: str
    task: Task
    threshold: float | None
    threshold_source: str


def is_task_path(text: str) -> bool:
    """Whether ENV reads as ``module:Class`` (a dotted module, a colon, a dotted Python name)
    rather than a gymnasium id (gymnasium's ``module:Env-v0`` has a version, not a Python name)."""
    module, sep, name = text.partition(":")
    return bool(sep) and all(p.isidentifier() for p in module.split(".")) and \
        all(p.isidentifier() for p in name.split("."))


def resolve_env(text: str) -> ResolvedEnv:
    """ENV as a task and its threshold (module docstring); ``EnvError`` if it cannot be."""
    if is_task_path(text):
        task = load_task(text)
        threshold = getattr(task, "reward_threshold", None)
        if threshold is not None and (isinstance(threshold, bool) or not isinstance(threshold, (int, float))
                                      or not math.isfinite(threshold)):
            raise EnvError(f"{text}.reward_threshold = {threshold!r}: make it a finite number, or None for no "
                           "threshold")
        source = "none" if threshold is None else f"{text}.reward_threshold"
        return ResolvedEnv(text, "task", task, None if threshold is None else float(threshold), source)
    task, threshold = gym_task(text)
    source = "none" if threshold is None else "gymnasium's reward_threshold"
    return ResolvedEnv(text, "gymnasium", task, threshold, source)


def _import(module: str, text: str):
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)  # a module in the current folder, as `python -m` finds it
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        parts = module.split(".")
        if exc.name in {".".join(parts[:k]) for k in range(1, len(parts) + 1)}:
            raise EnvError(f"{text}: there is no module {exc.name!r}: check the name, run from the folder that "
                           "holds it, or put its folder on PYTHONPATH") from None
        raise EnvError(f"{text}: importing {module!r} failed (ModuleNotFoundError: {exc}): install what it "
                       "imports") from None
    except Exception as exc:  # noqa: BLE001 - anything the user's module raises
        raise EnvError(f"{text}: importing {module!r} failed ({type(exc).__name__}: {exc}): fix the module") from None


def load_task(text: str) -> Task:
    """The task named by ``module:Class``: imported, made with no arguments, validated."""
    module_name, _, name = text.partition(":")
    obj = _import(module_name, text)
    for part in name.split("."):
        if not hasattr(obj, part):
            raise EnvError(f"{text}: module {module_name!r} has no attribute {name!r}: name a Task subclass it "
                           "defines")
        obj = getattr(obj, part)
    if not (isinstance(obj, type) and issubclass(obj, Task)):
        what = f"the class {obj.__name__}" if isinstance(obj, type) else f"an object of type {type(obj).__name__}"
        raise EnvError(f"{text} is {what}, not a subclass of evolution.Task: name a class that subclasses it")
    try:
        task = obj()
    except Exception as exc:  # noqa: BLE001 - anything the user's constructor raises
        raise EnvError(f"{text}() raised {type(exc).__name__}: {exc}: the class must be constructible with no "
                       "arguments") from None
    try:
        task.validate()
    except Exception as exc:  # noqa: BLE001 - TaskError, or whatever an overridden validate raises
        raise EnvError(f"{text} fails its own validation ({type(exc).__name__}: {exc}): fix the task") from None
    return task


# Thresholds gymnasium does not register but the field uses: Pendulum-v1's -200 (gymnax-blines'
# and the issue tracker's criterion for a swing-up that holds the pendulum up).
UNREGISTERED_THRESHOLDS = {"Pendulum-v1": -200.0}


def gym_task(env_id: str) -> tuple[Task, float | None]:
    """``(GymTask(env_id), gymnasium's reward_threshold)`` (module docstring)."""
    try:
        import gymnasium
    except ImportError:
        raise EnvError(f"{env_id!r} reads as a gymnasium id, but gymnasium is not installed: pip install "
                       "'snn-neat[gym]', or name your own task as module:Class") from None
    from evolution.task import TaskError
    from tasks.gym_adapter import GymTask

    try:
        spec = gymnasium.spec(env_id)
    except (gymnasium.error.Error, ImportError) as exc:
        raise EnvError(f"{env_id!r} is not a gymnasium environment id ({exc}): give a registered id such as "
                       "CartPole-v1, or your own task as module:Class") from None
    threshold = spec.reward_threshold if spec.reward_threshold is not None else UNREGISTERED_THRESHOLDS.get(env_id)
    try:
        task = GymTask(env_id)
    except (gymnasium.error.DependencyNotInstalled, ImportError) as exc:
        raise EnvError(f"gymnasium's {env_id} needs a package that is not installed here ({exc}): install it, "
                       "or choose another ENV") from None
    except (gymnasium.error.Error, TaskError) as exc:
        raise EnvError(f"gymnasium's {env_id} cannot run as a task here ({exc}): write it as your own "
                       "evolution.Task and give module:Class") from None
    return task, None if threshold is None else float(threshold)
