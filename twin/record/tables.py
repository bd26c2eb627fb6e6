"""A recording as Arrow tables: frames (one row per recorded frame, one column per scalar), events
and commands. Column names carry their unit; they come from the one Frame field description
(model.fields): a field added there fails here at import until it is given a column name.

Frame columns, in field order:
  step, t_ns                                      int64
  joint.<role>.position_rad|_m                    float64 (role: shoulder, elbow, z, wrist; z in m)
  joint.<role>.velocity_rad_s|_m_s, .effort_Nm|_N, .target_rad|_m
  suction.on                                      bool (the pad switched on)
  suction.sensed, suction.held                    int32 (object index in scene order, -1 none)
  hold.force_x_N .. hold.force_z_N, hold.torque_x_Nm .. _z_Nm   float64 (world axes)
  pad.x_m, pad.y_m, pad.z_m, pad.qx, pad.qy, pad.qz, pad.qw     float64 (pad tip, world frame)
  <object>.x_m .. <object>.qw                     float64 (each scene object by name)
  suction.command                                 bool: a suction signal was on for the physics
                                                  step that made this frame (Commands stamped
                                                  before it)

What twin.load and a replay return is a RecordingWithTables: the model's Recording, which is data
only, with to_arrow and to_pandas. pyarrow is imported when a table is built, not with the module.
"""

from __future__ import annotations

import json

import numpy as np

from twin.model.fields import FRAME_FIELDS
from twin.model.profiles import ROLES
from twin.model.recording import Recording

# The column stem of each Frame field; units and components come from model.fields.
_STEMS = {
    "step": "step",
    "t_ns": "t_ns",
    "joint_q": "position",
    "joint_qd": "velocity",
    "joint_effort": "effort",
    "joint_target": "target",
    "suction_on": "suction.on",
    "sensed_body": "suction.sensed",
    "held_body": "suction.held",
    "hold_force_n": "hold.force",
    "hold_torque_nm": "hold.torque",
    "pad_pose": "pad",
    "object_poses": "",
}
_POSE = ("x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")
_XYZ = ("x", "y", "z")
_PRISMATIC = ROLES.index("z")
# an object so named is `object.<name>`
_RESERVED = {"step", "t_ns", "joint", "suction", "hold", "pad"}


def _unit(field, *, prismatic: bool = False) -> str:
    """The field's unit as a column suffix: "rad|m" picks by joint type, "N·m" becomes Nm, "/"
    becomes _."""
    unit = field.compared[0].unit.split("|")[1 if prismatic else 0]
    return unit.replace("·", "").replace("/", "_")


def object_prefix(name: str) -> str:
    """An object's column prefix: its name, or `object.<name>` when the name is a fixed column's."""
    return f"object.{name}" if name in _RESERVED else name


def frame_column_names(object_names: list[str]) -> list[str]:
    """The frame table's column names (before suction.command), in order."""
    names: list[str] = []
    for f in FRAME_FIELDS:
        stem = _STEMS[f.name]
        if f.shape == "frame":
            names.append(stem)
        elif f.shape == "joint":
            names += [
                f"joint.{role}.{stem}_{_unit(f, prismatic=j == _PRISMATIC)}"
                for j, role in enumerate(ROLES)
            ]
        elif f.shape == "xyz":
            names += [f"{stem}_{axis}_{_unit(f)}" for axis in _XYZ]
        elif f.shape == "pose":
            names += [f"{stem}.{c}" for c in _POSE]
        else:  # object_pose
            names += [f"{object_prefix(obj)}.{c}" for obj in object_names for c in _POSE]
    return names


def frames_table(rec):
    """One row per recorded frame of a model.recording.Recording, one column per scalar (see module
    doc)."""
    import pyarrow as pa

    cols = rec.frames
    n = len(cols)
    arrays = []
    for f in FRAME_FIELDS:
        values = getattr(cols, f.name)
        flat = values.reshape(n, int(np.prod(values.shape[1:], dtype=np.int64)))
        arrays += [np.ascontiguousarray(flat[:, i]) for i in range(flat.shape[1])]
    names = frame_column_names([o.name for o in rec.config.objects])
    if len(names) != len(arrays):
        raise ValueError(
            f"recording {rec.path or '<memory>'}: {len(arrays)} frame columns for "
            f"{len(names)} names; "
            "its frames do not match its configuration's joints and objects"
        )
    arrays.append(suction_command(rec))
    names.append("suction.command")
    meta = {
        "twin.robot": rec.config.profile.name,
        "twin.objects": json.dumps([o.name for o in rec.config.objects]),
        "twin.rate_steps": str(rec.rate_steps),
    }
    return pa.table(dict(zip(names, arrays, strict=True)), metadata=meta)


def events_table(rec):
    """One row per Event: step, t_ns, kind, body, message, data_json (its data as JSON text)."""
    import pyarrow as pa

    ev = rec.events
    return pa.table(
        {
            "step": pa.array([e.step for e in ev], pa.int64()),
            "t_ns": pa.array([e.t_ns for e in ev], pa.int64()),
            "kind": pa.array([e.kind for e in ev], pa.string()),
            "body": pa.array([e.body for e in ev], pa.string()),
            "message": pa.array([e.message for e in ev], pa.string()),
            "data_json": pa.array([json.dumps(e.data, sort_keys=True) for e in ev], pa.string()),
        }
    )


def commands_table(rec):
    """One row per Command in recorded order: step, t_ns (when it took effect), kind, args_json."""
    import pyarrow as pa

    cmds = rec.commands
    dt_ns = rec.config.dt_ns
    return pa.table(
        {
            "step": pa.array([c.step for c in cmds], pa.int64()),
            "t_ns": pa.array([c.step * dt_ns for c in cmds], pa.int64()),
            "kind": pa.array([c.kind for c in cmds], pa.string()),
            "args_json": pa.array([json.dumps(c.args, sort_keys=True) for c in cmds], pa.string()),
        }
    )


def suction_command(rec) -> np.ndarray:
    """Per recorded frame: whether any of the robot's suction signals was on during the physics step
    that made it, from the Commands stamped before the frame's step (`signal` commands, and `key`
    commands through the recording's key map: its "signal" and "suction" actions)."""
    suction = rec.config.profile.suction_signals
    signals: dict[str, int] = {}
    changes_steps, changes_on = [], []
    for c in sorted(rec.commands, key=lambda c: c.step):
        for name, value in _signal_writes(c, rec.config.keymap, suction[0]):
            if value is None:
                signals.pop(name, None)
            else:
                signals[name] = int(value)
            changes_steps.append(c.step)
            changes_on.append(any(signals.get(s, 0) for s in suction))
    steps = rec.frames.step
    if not changes_steps:
        return np.zeros(len(steps), dtype=np.bool_)
    # the last change stamped before each frame's step (commands at s act on the step that makes
    # frame s+1)
    at = np.searchsorted(np.asarray(changes_steps, dtype=np.int64), steps, side="left") - 1
    on = np.asarray(changes_on, dtype=np.bool_)
    return np.where(at >= 0, on[np.maximum(at, 0)], False)


def _signal_writes(command, keymap: dict, first_suction: str):
    """The (signal name, value) pairs a Command sets, in order."""
    if command.kind == "signal":
        yield command.args["name"], command.args["value"]
    elif command.kind == "key":
        for action in keymap.get(command.args["key"], ()):
            if action[0] == "signal":
                yield action[1], action[2]
            elif action[0] == "suction":
                yield first_suction, int(action[1])


class RecordingWithTables(Recording):
    """A Recording whose frames, events and commands also come as tables: what twin.load and a
    replay return."""

    def to_arrow(self, table: str = "frames"):
        """The recording as a pyarrow Table: "frames" (one row per recorded frame, one column per
        scalar, units in the names), "events" or "commands"; the columns are described in
        record.tables."""
        builders = {"frames": frames_table, "events": events_table, "commands": commands_table}
        if table not in builders:
            raise ValueError(f"table {table!r} is unknown; expected one of {', '.join(builders)}")
        return builders[table](self)

    def to_pandas(self, table: str = "frames"):
        """to_arrow(table) as a pandas DataFrame (pandas is optional: `pip install pandas`)."""
        try:
            import pandas  # noqa: F401 - only to say clearly that it is missing
        except ImportError:
            raise ImportError(
                "Recording.to_pandas needs the pandas package: pip install pandas"
            ) from None
        return self.to_arrow(table).to_pandas()
