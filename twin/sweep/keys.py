"""The keys a sweep varies and how a value reaches the run: a scene object's field (`box.x_m`), the
suction pad's (`pad.max_pull_force_n`), the robot's joint speeds and strengths (`robot.*`), engine
settings (`engine.*`) or a task parameter (`task.cycles`).

Scene, pad, robot and engine values change the TwinConfig (a frozen dataclass, checked against the
configuration's schema, so the value is stored in the recording and a replay rebuilds the run);
task values become task parameters, checked against the task function's signature.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
from dataclasses import dataclass

from twin.model.config import SUCTION_SCHEMA, TwinConfig
from twin.model.errors import ConfigError
from twin.sweep.dists import Dist
from twin.tasks import TaskFn, task_params

OBJECT_FIELDS = {
    "x_m": ("pos_m", 0),
    "y_m": ("pos_m", 1),
    "z_m": ("pos_m", 2),
    "yaw_rad": ("yaw_rad", None),
    "mass_kg": ("mass_kg", None),
    "friction": ("friction", None),
}
ROBOT_FIELDS = (
    "revolute_max_velocity_rad_s",
    "prismatic_max_velocity_m_s",
    "revolute_max_torque_nm",
    "prismatic_max_force_n",
)
ENGINE_FIELDS = (
    "num_solver_iterations",
    "position_gain",
    "velocity_gain",
    "solver_residual_threshold",
)
PAD_FIELDS = tuple(SUCTION_SCHEMA)


@dataclass(frozen=True)
class Key:
    """A varied key: `name` as written; `part` is "object", "pad", "robot", "engine" or "task";
    `owner` the object's name (objects only); `field` the dataclass field or task parameter; `index`
    the component of a tuple field (pos_m) or None."""

    name: str
    part: str
    field: str
    owner: str = ""
    index: int | None = None


def resolve_key(
    name: str, config: TwinConfig, fn: TaskFn, task: str, *, option: str = "--vary"
) -> Key:
    """The Key a name means on this configuration and task; ConfigError naming the option (--vary,
    or twin run's --set) and what is expected."""
    head, dot, tail = name.partition(".")
    objects = [o.name for o in config.objects]
    if not dot or not tail:
        raise ConfigError(
            f"{option} key {name!r} is invalid; expected PART.FIELD: {_expected(objects)}"
        )
    if head == "task":
        known = task_params(fn)
        if known is not None and tail not in known:
            raise ConfigError(
                f"{option} key {name!r}: task {task!r} takes no parameter {tail!r}; "
                f"its parameters: {', '.join(known) or 'none'}"
            )
        return Key(name, "task", tail)
    fields = {"pad": PAD_FIELDS, "robot": ROBOT_FIELDS, "engine": ENGINE_FIELDS}.get(head)
    if fields is not None:
        if tail not in fields:
            raise ConfigError(
                f"{option} key {name!r} is unknown; expected {head}. followed by one of "
                f"{', '.join(fields)}"
            )
        return Key(name, head, tail)
    if head in objects:
        if tail not in OBJECT_FIELDS:
            raise ConfigError(
                f"{option} key {name!r} is unknown; expected {head}. followed by one of "
                f"{', '.join(OBJECT_FIELDS)}"
            )
        field, index = OBJECT_FIELDS[tail]
        return Key(name, "object", field, head, index)
    raise ConfigError(f"{option} key {name!r} is unknown; expected {_expected(objects)}")


def _expected(objects: list[str]) -> str:
    names = "/".join(objects) or "(no objects)"
    return (
        f"<object>.x_m|y_m|z_m|yaw_rad|mass_kg|friction (objects: {names}), pad.<field>, "
        "robot.<joint speed or strength>, engine.<field> or task.<parameter>"
    )


def check_dist(key: Key, dist: Dist, config: TwinConfig, fn: TaskFn) -> None:
    """Refuse, before anything runs, a distribution the key cannot take: every candidate value
    (both ends of a uniform, a normal's mean, each choice) must be valid for the field."""
    if key.part == "task":
        _check_task_values(key, dist, fn)
        return
    for value in dist.candidates():
        apply_values(config, {key: value}, where=f"--vary {key.name}={dist.text}")


def _check_task_values(key: Key, dist: Dist, fn: TaskFn) -> None:
    """A task parameter with a default takes values of the default's type (bool, int, float,
    str)."""
    param = (task_params(fn) or {}).get(key.field)
    default = None if param is None or param.default is inspect.Parameter.empty else param.default
    if default is None:
        return
    kind = type(default)
    if kind is bool:
        ok = not dist.real and all(isinstance(v, bool) for v in dist.candidates())
    elif kind is int:
        ok = not dist.real and all(
            isinstance(v, int) and not isinstance(v, bool) for v in dist.candidates()
        )
    elif kind is float:
        ok = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in dist.candidates())
    else:
        ok = kind is not str or (
            not dist.real and all(isinstance(v, str) for v in dist.candidates())
        )
    if not ok:
        raise ConfigError(
            f"--vary {key.name}={dist.text} is invalid; the task's {key.field} takes "
            f"{kind.__name__} values (its default is {default!r})"
        )


def apply_values(
    config: TwinConfig, values: dict[Key, object], where: str = "scenario"
) -> TwinConfig:
    """config with the non-task values set, checked against the configuration's schema (the check a
    recording's configuration gets); ConfigError naming the key and value that are invalid."""
    changed = config
    for key, value in values.items():
        if key.part != "task":
            changed = _set(changed, key, value)
    if changed is config:
        return config
    try:
        TwinConfig.from_dict(json.loads(json.dumps(changed.to_dict())))
    except (ConfigError, TypeError, ValueError) as err:
        for key, value in values.items():  # name the value at fault
            if key.part != "task":
                try:
                    TwinConfig.from_dict(json.loads(json.dumps(_set(config, key, value).to_dict())))
                except (ConfigError, TypeError, ValueError) as one:
                    raise ConfigError(
                        f"{where}: {key.name} = {value!r} is invalid ({one})"
                    ) from None
        raise ConfigError(f"{where}: {err}") from None
    return changed


def task_values(values: dict[Key, object]) -> dict:
    """The task parameters among the values."""
    return {key.field: value for key, value in values.items() if key.part == "task"}


def _set(config: TwinConfig, key: Key, value: object) -> TwinConfig:
    """config with one field replaced (no check)."""
    if key.part == "object":
        objects = list(config.objects)
        i = [o.name for o in objects].index(key.owner)
        old = getattr(objects[i], key.field)
        new = (
            value
            if key.index is None
            else tuple(value if j == key.index else v for j, v in enumerate(old))
        )
        objects[i] = dataclasses.replace(objects[i], **{key.field: new})
        return dataclasses.replace(config, objects=tuple(objects))
    if key.part == "pad":
        return dataclasses.replace(
            config, suction=dataclasses.replace(config.suction, **{key.field: value})
        )
    if key.part == "robot":
        return dataclasses.replace(
            config, profile=dataclasses.replace(config.profile, **{key.field: value})
        )
    return dataclasses.replace(
        config, engine=dataclasses.replace(config.engine, **{key.field: value})
    )
