"""A joint log: one robot's joint states at its own sample times, as a ROS 2 bag's `/joint_states`
holds them (twin.ros2 reads one) or as a twin run's frames give them (`from_recording`).

Times are integer nanoseconds on the log's own clock (wall-clock for a real robot, simulated time
for a twin run); a value a log does not carry (a bag without velocities) is None.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from twin.model.errors import ConfigError
from twin.model.recording import Recording


@dataclass
class JointLog:
    """Joint states by name, sampled at `t_ns`.

    Attributes:
        names: the joints, in column order.
        t_ns: sample times (n,), increasing, in the log's own clock.
        position_rad: (n, joints) positions (rad, m for a prismatic joint).
        velocity_rad_s: (n, joints) velocities, or None when the log has none.
        effort_nm: (n, joints) efforts (N·m, N), or None when the log has none.
        path: where it was read from ("" in memory).
        topics: the source's topics and types (a bag's), for `twin info`-like summaries.
        tf: other frames' poses by child frame: (t_ns (m,), poses (m, 7)) where the source has /tf.
        notes: what reading it left out, said in a comparison's report.
    """

    names: tuple[str, ...]
    t_ns: np.ndarray
    position_rad: np.ndarray
    velocity_rad_s: np.ndarray | None = None
    effort_nm: np.ndarray | None = None
    path: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    tf: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def rate_hz(self) -> float:
        """The median sample rate (0 for fewer than two samples)."""
        if len(self.t_ns) < 2:
            return 0.0
        return float(1e9 / np.median(np.diff(self.t_ns)))

    @staticmethod
    def from_recording(rec: Recording, object_frames: tuple[str, ...] | None = None) -> JointLog:
        """A twin run's joints at its recorded frames (simulated time), with the pad tip's and
        each object's poses as `tf` (`pad_tip`, and each object by `object_frames`, the names an
        exported bag's /tf gives them; by default the objects' own names)."""
        frames = rec.frames
        t_ns = np.asarray(frames.t_ns, dtype=np.int64)
        names = object_frames or tuple(o.name for o in rec.config.objects)
        tf = {"pad_tip": (t_ns, np.asarray(frames.pad_pose, dtype=np.float64))}
        for k, name in enumerate(names):
            tf.setdefault(name, (t_ns, np.asarray(frames.object_poses[:, k], dtype=np.float64)))
        return JointLog(
            tuple(rec.config.profile.joint_names),
            np.asarray(frames.t_ns, dtype=np.int64),
            np.asarray(frames.joint_q, dtype=np.float64),
            np.asarray(frames.joint_qd, dtype=np.float64),
            np.asarray(frames.joint_effort, dtype=np.float64),
            path=rec.path,
            tf=tf,
        )

    def renamed(self, joint_map: dict[str, str]) -> JointLog:
        """The same log with joints renamed (ROBOT name -> TWIN name); ConfigError naming a
        ROBOT name the log does not have."""
        missing = [name for name in joint_map if name not in self.names]
        if missing:
            raise ConfigError(
                f"--joint-map names {missing[0]!r}, which {self.path or 'the log'} does not have; "
                f"expected one of {', '.join(self.names)}"
            )
        names = tuple(joint_map.get(name, name) for name in self.names)
        return JointLog(
            names=names,
            t_ns=self.t_ns,
            position_rad=self.position_rad,
            velocity_rad_s=self.velocity_rad_s,
            effort_nm=self.effort_nm,
            path=self.path,
            topics=self.topics,
            tf=self.tf,
            notes=self.notes,
        )


def parse_joint_map(specs: list[str]) -> dict[str, str]:
    """`ROBOT=TWIN` pairs as a dict; ConfigError naming a malformed one."""
    out: dict[str, str] = {}
    for spec in specs:
        robot, sep, twin_name = spec.partition("=")
        if not sep or not robot.strip() or not twin_name.strip():
            raise ConfigError(f"--joint-map {spec!r} is malformed; expected ROBOT=TWIN")
        out[robot.strip()] = twin_name.strip()
    return out
