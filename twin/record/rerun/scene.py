"""What a Rerun recording of a run looks like: entity paths, colours, the static scene and the
blueprint.

The robot is drawn by Rerun's own URDF loader (its links live in named frames, one per URDF link);
everything else lives in the world frame. Only record/ imports rerun.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, RecordingError
from twin.robot.urdf import PAD_RADIUS_M, UrdfJoint, urdf_joints

APPLICATION_ID = "twin"
ROLES = ("shoulder", "elbow", "z", "wrist")
ROBOT_PATH = "robot"
# one animated Transform3D per driven joint, in the URDF's named frames
JOINTS_PATH = "robot/joints"
WORLD_PATH = "world"
OBJECTS_PATH = "world/objects"
PAD_PATH = "world/pad"
ANGLES_PATH = "plots/joints_rad"
Z_PATH = "plots/z_m"
SUCTION_PATH = "plots/suction"
EVENTS_PATH = "events"
COMMANDS_PATH = "commands"
CAMERAS_PATH = "world/cameras"  # one entity per camera: its Pinhole (static), pose and pictures
STEP_TIMELINE = "step"
TIME_TIMELINE = "sim_time"

PAD_MARGIN_M = 0.003  # the coloured sleeve is this much larger than the pad, so it shows around it
PAD_OFF_RGB = (150, 150, 150)
PAD_ON_RGB = (240, 190, 40)  # sucking, nothing held
PAD_HOLDING_RGB = (40, 210, 90)
PAD_RGBS = (PAD_OFF_RGB, PAD_ON_RGB, PAD_HOLDING_RGB)  # what pad_color_index indexes
JOINT_RGB = {
    "shoulder": (70, 160, 255),
    "elbow": (255, 140, 50),
    "z": (230, 200, 60),
    "wrist": (120, 220, 120),
}
TARGET_WIDTH_PX = 1.0
ACTUAL_WIDTH_PX = 2.5

EVENT_LEVELS = {
    "task_error": "ERROR",
    "break": "ERROR",
    "out_of_reach": "WARN",
    "settle_timeout": "WARN",
    "joint_limit": "WARN",
    "suction_empty": "WARN",
    "key_unknown": "WARN",
}


def object_path(name: str) -> str:
    return f"{OBJECTS_PATH}/{rr.escape_entity_path_part(name)}"


def camera_path(name: str) -> str:
    return f"{CAMERAS_PATH}/{rr.escape_entity_path_part(name)}"


def joint_path(name: str) -> str:
    return f"{JOINTS_PATH}/{rr.escape_entity_path_part(name)}"


def pad_color_index(suction_on: np.ndarray, held_body: np.ndarray) -> np.ndarray:
    """Per-frame colour of the pad marker, as an index into PAD_RGBS: grey off, amber sucking,
    green holding."""
    index = suction_on.astype(np.intp)  # off 0, on 1: PAD_RGBS' first two
    index[held_body >= 0] = PAD_RGBS.index(PAD_HOLDING_RGB)
    return index


def load_urdf_tree(config: TwinConfig, urdf_text: str) -> rr.urdf.UrdfTree:
    """Parse the robot's URDF with Rerun's loader: the user's file in place (so its meshes resolve),
    otherwise the text written to a temporary file."""
    user_path = Path(config.profile.urdf_path) if config.profile.urdf_path else None
    try:
        if user_path is not None and user_path.is_file() and user_path.read_text() == urdf_text:
            return rr.urdf.UrdfTree.from_file_path(user_path, ROBOT_PATH)
        with tempfile.TemporaryDirectory(prefix="twin-urdf-") as tmp:
            path = Path(tmp) / f"{config.profile.name or 'robot'}.urdf"
            path.write_text(urdf_text)
            return rr.urdf.UrdfTree.from_file_path(path, ROBOT_PATH)
    except (OSError, ValueError, RuntimeError) as err:
        raise RecordingError(
            f"cannot draw the URDF of robot {config.profile.name!r}: {err}"
        ) from err


def driven_joints(config: TwinConfig, urdf_text: str) -> list[UrdfJoint]:
    """The URDF joints for shoulder, elbow, Z and wrist, in profile order."""
    try:
        by_name = {j.name: j for j in urdf_joints(urdf_text)}
    except ConfigError as err:
        raise RecordingError(
            f"cannot draw the URDF of robot {config.profile.name!r}: {err}"
        ) from err
    missing = [name for name in config.profile.joint_names if name not in by_name]
    if missing:
        raise RecordingError(
            f"URDF of robot {config.profile.name!r} has no joint {missing[0]!r}; "
            f"it has {sorted(by_name)}"
        )
    return [by_name[name] for name in config.profile.joint_names]


def log_static_scene(
    stream: rr.RecordingStream, config: TwinConfig, tree: rr.urdf.UrdfTree
) -> None:
    """Everything that does not change over a run, logged once."""
    stream.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    tree.log_urdf_to_recording(stream)
    # The robot base stands at the world origin: tie the URDF's root frame to the world's frame.
    stream.log(
        f"{ROBOT_PATH}/base_in_world",
        rr.Transform3D(parent_frame="tf#/", child_frame=tree.root_link().name),
        static=True,
    )
    for obj in config.objects:
        rgba = tuple(round(255 * c) for c in obj.rgba)
        stream.log(
            object_path(obj.name),
            rr.Boxes3D(
                half_sizes=[np.asarray(obj.size_m) / 2],
                colors=[rgba],
                fill_mode="solid",
                labels=[obj.name],
                show_labels=False,
            ),
            static=True,
        )
    # The pad's state colours a sleeve over the pad, from its tip up to its root (positions: the
    # tip).
    pad_m = config.profile.pad_length_m
    stream.log(
        PAD_PATH,
        rr.Cylinders3D.from_fields(
            lengths=[pad_m + PAD_MARGIN_M], radii=[PAD_RADIUS_M + PAD_MARGIN_M], fill_mode="solid"
        ),
        static=True,
    )
    for cam in config.cameras:  # pictures and poses come with each picture (RerunRecorder.on_image)
        k = cam.intrinsics()
        stream.log(
            camera_path(cam.name),
            rr.Pinhole(
                image_from_camera=[k[0:3], k[3:6], k[6:9]],
                resolution=[cam.width_px, cam.height_px],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.1,
            ),
            static=True,
        )
    for role in ("shoulder", "elbow", "wrist"):
        _series_style(
            stream, f"{ANGLES_PATH}/{role}", f"{role} q", JOINT_RGB[role], ACTUAL_WIDTH_PX
        )
        _series_style(
            stream,
            f"{ANGLES_PATH}/{role}_target",
            f"{role} target",
            JOINT_RGB[role],
            TARGET_WIDTH_PX,
        )
    _series_style(stream, f"{Z_PATH}/z", "z q", JOINT_RGB["z"], ACTUAL_WIDTH_PX)
    _series_style(stream, f"{Z_PATH}/z_target", "z target", (200, 200, 200), TARGET_WIDTH_PX)
    _series_style(stream, f"{SUCTION_PATH}/on", "suction on", PAD_ON_RGB, ACTUAL_WIDTH_PX)
    _series_style(stream, f"{SUCTION_PATH}/holding", "holding", PAD_HOLDING_RGB, ACTUAL_WIDTH_PX)


def _series_style(
    stream: rr.RecordingStream, path: str, name: str, rgb: tuple[int, int, int], width_px: float
) -> None:
    stream.log(path, rr.SeriesLines(names=[name], colors=[rgb], widths=[width_px]), static=True)


def blueprint(config: TwinConfig, *, play_state: str | None = None) -> rrb.Blueprint:
    """A 3D view of the robot and boxes beside the joint plots, suction state and event log.

    play_state "following" opens on the end of the run (screenshots); None lets the viewer play from
    the start.
    """
    reach_m = config.profile.link1_m + config.profile.link2_m
    view_3d = rrb.Spatial3DView(
        name="robot",
        origin="/",
        contents=[
            f"+ /{WORLD_PATH}/**",
            f"+ /{ROBOT_PATH}/**",
            f"- /{ROBOT_PATH}/**/collision_geometries/**",
        ],
        # The whole workspace at every moment: the arm at full reach in any direction, pick_place's
        # pick (0.2, 0.7) and place (-0.3, -0.55) points and the box between them; from the front
        # right, above.
        eye_controls=rrb.EyeControls3D(
            position=(1.45 * reach_m, -1.7 * reach_m, 1.3 * reach_m),
            look_target=(0.0, 0.0, 0.05),
            eye_up=(0, 0, 1),
        ),
        # URDF links carry a colour but no fill mode: draw them as solids, not wireframes.
        defaults=[
            rr.Boxes3D.from_fields(fill_mode="solid"),
            rr.Cylinders3D.from_fields(fill_mode="solid"),
        ],
    )
    limits = config.profile.joint_limits()
    angle_rad = max(abs(v) for lo_hi in (limits[0], limits[1], limits[3]) for v in lo_hi)
    z_margin_m = 0.05 * config.profile.z_stroke_m
    plots = rrb.Vertical(
        rrb.TimeSeriesView(
            name="arm joints: q and target (rad)",
            origin=f"/{ANGLES_PATH}",
            axis_y=rrb.ScalarAxis(range=(-angle_rad, angle_rad)),
        ),
        rrb.TimeSeriesView(
            name="Z joint: q and target (m, + lowers)",
            origin=f"/{Z_PATH}",
            axis_y=rrb.ScalarAxis(range=(limits[2][0] - z_margin_m, limits[2][1] + z_margin_m)),
        ),
        rrb.TimeSeriesView(
            name="suction (1 = on / holding)",
            origin=f"/{SUCTION_PATH}",
            axis_y=rrb.ScalarAxis(range=(-0.1, 1.1)),
        ),
        rrb.TextLogView(
            name="events",
            origin=f"/{EVENTS_PATH}",
            columns=rrb.TextLogColumns(
                text_log_columns=[
                    TextLogColumn("LogLevel"),
                    TextLogColumn("Body"),
                    TextLogColumn("EntityPath", visible=False),
                ]
            ),
        ),
        row_shares=[3, 2, 1.5, 2],
    )
    main = rrb.Horizontal(view_3d, plots, column_shares=[5, 4])
    if config.cameras:  # each camera's pictures in a column beside the 3D view
        pictures = rrb.Vertical(
            *(
                rrb.Spatial2DView(name=f"camera {c.name}", origin=f"/{camera_path(c.name)}")
                for c in config.cameras
            )
        )
        main = rrb.Horizontal(view_3d, pictures, plots, column_shares=[5, 2.5, 4])
    return rrb.Blueprint(
        main,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline=TIME_TIMELINE, state="collapsed", play_state=play_state),
    )
