"""Built-in tasks (plain functions `run(twin, **params)`) and loading a user's task file."""

from __future__ import annotations

import importlib.util
import inspect
import sys
from collections.abc import Callable
from pathlib import Path

from twin.errors import ConfigError, TaskError, TwinError
from twin.tasks import pick_place, seed000, seed001, seed002

TaskFn = Callable[..., None]
TASKS: dict[str, TaskFn] = {"pick_place": pick_place.run, "seed000": seed000.run, "seed001": seed001.run,
                             "seed002": seed002.run}


def resolve(name_or_path: str) -> TaskFn:
    """A built-in task by name, or the `run` function of a Python file."""
    if name_or_path in TASKS:
        return TASKS[name_or_path]
    path = Path(name_or_path)
    if path.suffix != ".py":
        raise ConfigError(f"unknown task {name_or_path!r}; expected one of {', '.join(TASKS)} or a .py file")
    if not path.is_file():
        raise ConfigError(f"task file {name_or_path!r} does not exist")
    spec = importlib.util.spec_from_file_location(f"twin_user_task_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and pickling look a module up by its name
    try:
        spec.loader.exec_module(module)
    except Exception as err:  # a user's file: report, do not crash
        sys.modules.pop(spec.name, None)
        raise ConfigError(f"task file {name_or_path!r} failed to import: {type(err).__name__}: {err}") from err
    fn = getattr(module, "run", None)
    if not callable(fn):
        raise ConfigError(f"task file {name_or_path!r} has no function run(twin, **params)")
    return fn


def accepted_params(fn: TaskFn, params: dict) -> dict:
    """The subset of params the task's signature accepts (so --cycles only reaches tasks that take it)."""
    sig = inspect.signature(fn)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return dict(params)
    return {k: v for k, v in params.items() if k in sig.parameters}


def run_task(twin, fn: TaskFn, params: dict) -> None:
    """Run a task; any exception becomes an Event and a TaskError (OutOfReach etc. pass as they are)."""
    twin.event("task_start", message=getattr(fn, "__module__", "task"), **params)
    try:
        fn(twin, **params)
    except TwinError as err:
        twin.event("task_error", message=f"{type(err).__name__}: {err}")
        raise
    except Exception as err:
        twin.event("task_error", message=f"{type(err).__name__}: {err}")
        raise TaskError(f"task raised {type(err).__name__}: {err}") from err
    twin.event("task_end")
