"""Built-in tasks (plain functions `run(twin, **params)`) and loading a user's task file."""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import sys
from collections.abc import Callable
from pathlib import Path

from twin.model.errors import ConfigError, TaskError, TaskTimeout, TwinError, exception_text
from twin.model.sink import Sink
from twin.tasks import pick_place, pick_place_vision, seed000, seed001, seed002

TaskFn = Callable[..., None]
TASKS: dict[str, TaskFn] = {
    "pick_place": pick_place.run,
    "seed000": seed000.run,
    "seed001": seed001.run,
    "seed002": seed002.run,
    "pick_place_vision": pick_place_vision.run,
}


def resolve(name_or_path: str) -> TaskFn:
    """A built-in task by name, or the `run` function of a Python file."""
    if name_or_path in TASKS:
        return TASKS[name_or_path]
    path = Path(name_or_path)
    if path.suffix != ".py":
        raise ConfigError(
            f"unknown task {name_or_path!r}; expected one of {', '.join(TASKS)} or a .py file"
        )
    if not path.is_file():
        raise ConfigError(f"task file {name_or_path!r} does not exist")
    spec = importlib.util.spec_from_file_location(f"twin_user_task_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and pickling look a module up by its name
    try:
        spec.loader.exec_module(module)
    except Exception as err:  # a user's file: report, do not crash
        sys.modules.pop(spec.name, None)
        raise ConfigError(
            f"task file {name_or_path!r} failed to import: {type(err).__name__}: {err}"
        ) from err
    fn = getattr(module, "run", None)
    if not callable(fn):
        raise ConfigError(f"task file {name_or_path!r} has no function run(twin, **params)")
    return fn


def accepted_params(fn: TaskFn, params: dict) -> dict:
    """The subset of params the task's signature accepts (so --cycles only reaches tasks that take
    it)."""
    sig = inspect.signature(fn)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return dict(params)
    return {k: v for k, v in params.items() if k in sig.parameters}


def task_params(fn: TaskFn) -> dict[str, inspect.Parameter] | None:
    """The keyword parameters a task takes after `twin` (name -> Parameter); None when it takes
    **params."""
    sig = inspect.signature(fn)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return None
    return {
        name: p
        for name, p in list(sig.parameters.items())[1:]
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    }


def check_params(fn: TaskFn, params: dict, task: str) -> dict:
    """params, each one checked against the task's signature: a name the task does not take is a
    ConfigError (exit 2) naming it and the ones it takes, never silently dropped."""
    known = task_params(fn)
    if known is not None:
        for name in params:
            if name not in known:
                takes = ", ".join(known) or "none"
                raise ConfigError(
                    f"task {task!r} takes no parameter {name!r}; its parameters: {takes}"
                )
    return dict(params)


def source_sha256(path: str | Path) -> str:
    """The sha256 of a source file with its line ends made LF, so a checkout with CRLF names the
    same task."""
    return hashlib.sha256(Path(path).read_bytes().replace(b"\r\n", b"\n")).hexdigest()


def task_identity(fn: TaskFn) -> str:
    """What a recording names a task by: the content of its source file (`sha256:<hex>`), so the
    same task run by name, from its file or from a renamed copy is the same task. A function with no
    source file is named by its module and name."""
    try:
        path = inspect.getsourcefile(fn)
    except TypeError:
        path = None
    if path and Path(path).is_file():
        return "sha256:" + source_sha256(path)
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', 'task')}"


def run_task(twin, fn: TaskFn, params: dict) -> None:
    """Run a task; any exception becomes a task_error Event and a TaskError (a TwinError such as
    OutOfReach passes as it is). A task that calls sys.exit has failed too, whatever the code:
    only returning ends a task well."""
    twin.event("task_start", message=task_identity(fn), **params)
    try:
        fn(twin, **params)
    except TwinError as err:
        twin.event("task_error", message=f"{type(err).__name__}: {err}")
        raise
    except SystemExit as err:
        text = f"the task called sys.exit({exception_text(err)}) instead of returning"
        twin.event("task_error", message=f"SystemExit: {text}")
        raise TaskError(text) from err
    except Exception as err:
        text = f"{type(err).__name__}: {exception_text(err)}"
        twin.event("task_error", message=text)
        raise TaskError(f"task raised {text}") from err
    twin.event("task_end")


class TimeLimit(Sink):
    """A sink that ends a task run at the first frame past `limit_s` of simulated time
    (`--timeout`): an endless task would otherwise record until the disk is full. Put it after the
    recorders, so they hold that frame too; it raises again on every later frame, so a task that
    catches the error cannot run on."""

    reads_pad_pose = False  # only t_ns

    def __init__(self, limit_s: float) -> None:
        self.limit_s = limit_s
        self._limit_ns = round(limit_s * 1e9)

    def on_frame(self, frame) -> None:
        if frame.t_ns > self._limit_ns:
            raise TaskTimeout(
                f"task ran past --timeout {self.limit_s:g} s of simulated time "
                f"(stopped at t = {frame.t_ns * 1e-9:.3f} s)"
            )
