"""A scene file (`twin run --scene FILE.toml`): the boxes on the floor, one `[[box]]` table each
with a scene object's fields (name; optional size_m, mass_kg, pos_m, yaw_rad, friction, rgba, each
defaulting as `SceneObject` does). They become the configuration's objects, which a recording
stores, so `twin replay` and `twin check` rebuild the same scene from the recording alone."""

from __future__ import annotations

import os
from pathlib import Path

from twin.model.config import MAX_OBJECTS, SceneObject, TwinConfig, scene_object
from twin.model.errors import ConfigError
from twin.model.json_values import load_toml_text

MAX_BYTES = 1 << 20  # a scene of 100 boxes is a few kilobytes


def read_scene(path: str | os.PathLike) -> tuple[SceneObject, ...]:
    """The scene file's boxes in file order (the order the world creates them in); ConfigError
    (exit 2) naming the file and the box or field at fault."""
    p = Path(path)
    what = f"--scene {str(path)!r}"
    if p.suffix != ".toml":
        raise ConfigError(f"{what} should end in .toml")
    try:
        with open(p, "rb") as f:
            raw = f.read(MAX_BYTES + 1)
    except OSError as err:
        raise ConfigError(f"{what} cannot be read: {err.strerror or err}") from err
    if len(raw) > MAX_BYTES:
        raise ConfigError(f"{what} is over {MAX_BYTES} bytes; expected a scene file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(f"{what} is not UTF-8 text; expected a TOML scene file") from None
    data = load_toml_text(text, what)
    unknown = sorted(k for k in data if k != "box")
    if unknown:
        raise ConfigError(
            f"{what} has unknown table {unknown[0][:60]!r}; expected only [[box]] tables"
        )
    boxes = data.get("box")
    if not isinstance(boxes, list) or not boxes or len(boxes) > MAX_OBJECTS:
        raise ConfigError(f"{what} holds no [[box]] tables; expected 1..{MAX_OBJECTS} of them")
    objects = []
    for i, box in enumerate(boxes):
        if not isinstance(box, dict) or "name" not in box:
            raise ConfigError(f"{what}: box {i + 1} has no name; expected name = \"...\"")
        try:
            objects.append(scene_object(box, f"box {i + 1} ({str(box['name'])[:40]})"))
        except ConfigError as err:
            raise ConfigError(f"{what}: {err}") from None
    try:
        TwinConfig(objects=tuple(objects))  # names unique
    except ConfigError as err:
        raise ConfigError(f"{what}: {err}") from None
    return tuple(objects)
