"""A loaded recording's pictures as the CameraImages sinks get (Sink.on_image): what write_rrd draws
and what a replay's feed hands on, each with the pose its camera's track holds."""

from __future__ import annotations

import numpy as np

from twin.model.images import CameraImage, CameraSpec, CameraTrack, camera_view, optical_pose


def recorded_images(
    cameras: tuple[CameraSpec, ...],
    by_name: dict[str, CameraTrack],
    frame_steps: np.ndarray,
    pad_poses: np.ndarray,
) -> list[CameraImage]:
    """A recording's pictures as CameraImages in step order (camera order within a step), each with
    the pose its track holds (the file's /tf). A track without poses (a file that holds none) has
    them worked out from the recorded frame at (or, in a decimated file, just before) its step."""
    out = []
    for spec in cameras:
        track = by_name.get(spec.name)
        if track is None or not len(frame_steps):
            continue
        held = len(track.pose) == len(track)
        for i in range(len(track)):
            step = int(track.step[i])
            if held:
                pose = tuple(track.pose[i].tolist())
            else:
                row = max(0, int(np.searchsorted(frame_steps, step, side="right")) - 1)
                pose = optical_pose(*camera_view(spec, tuple(pad_poses[row].tolist())))
            out.append(
                CameraImage(
                    camera=spec.name,
                    step=step,
                    t_ns=int(track.t_ns[i]),
                    format=track.format,
                    data=track.data[i],
                    pose=pose,
                )
            )
    return sorted(out, key=lambda im: im.step)
