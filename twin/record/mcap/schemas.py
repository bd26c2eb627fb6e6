"""What each MCAP channel carries: topics, schema names, encodings and the schema bytes.

The twin's per-step blocks are protobuf messages (proto3, packed repeated fields, row-major
[frame][item]) described by a FileDescriptorSet built here, so a third party decodes them from the
file alone. Transforms and events use Foxglove's well-known schemas; commands and events-with-data
are JSON with a JSON Schema.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache

from google.protobuf import descriptor_pb2

from twin.model import fields as F
from twin.model.recording import (  # noqa: F401 - named once, in the model
    META_FINALIZED,
    META_MACHINE,
    META_RECORDING,
)
from twin.model.types import COMMAND_ARGS

BLOCKS_PROTO = "twin/blocks.proto"

# field numbers, shared by the writer's encoder and the reader's fast path (model.fields holds them)
STEP, T_NS, NAMES = F.BY_NAME["step"].number, F.BY_NAME["t_ns"].number, F.NAMES_FIELD

_F = descriptor_pb2.FieldDescriptorProto
_PROTO_TYPES = {
    "<f8": _F.TYPE_DOUBLE,
    "<i8": _F.TYPE_SFIXED64,
    "<i4": _F.TYPE_SFIXED32,
    "|u1": _F.TYPE_BOOL,
}


def _block_fields(block: str) -> list[tuple[str, int, int]]:
    """(name, number, protobuf type) of a block message's fields: step, t_ns, its names, then its
    Frame fields."""
    step, t_ns, *rest = F.block_fields(block)
    return (
        [(f.proto_name, f.number, _PROTO_TYPES[f.wire]) for f in (step, t_ns)]
        + [(F.NAMES_FIELD_NAME[block], F.NAMES_FIELD, _F.TYPE_STRING)]
        + [(f.proto_name, f.number, _PROTO_TYPES[f.wire]) for f in rest]
    )


_BLOCK_FIELDS: dict[str, list[tuple[str, int, int]]] = {
    block: _block_fields(block) for block in F.BLOCKS
}


@cache
def blocks_descriptor_set() -> bytes:
    """The FileDescriptorSet of twin/blocks.proto (JointBlock, SuctionBlock, PoseBlock)."""
    fd = descriptor_pb2.FileDescriptorProto(name=BLOCKS_PROTO, package="twin", syntax="proto3")
    for message, fields in _BLOCK_FIELDS.items():
        m = fd.message_type.add(name=message)
        for name, number, kind in fields:
            m.field.add(
                name=name,
                number=number,
                type=kind,
                label=_F.LABEL_REPEATED,
                json_name=_json_name(name),
            )
    return descriptor_pb2.FileDescriptorSet(file=[fd]).SerializeToString(deterministic=True)


def _json_name(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(part.capitalize() for part in rest)


@cache
def foxglove_descriptor_set(message_name: str) -> bytes:
    """FileDescriptorSet of a Foxglove well-known message ('FrameTransforms', 'Log') and its
    imports."""
    import importlib

    module = importlib.import_module(f"foxglove_schemas_protobuf.{message_name}_pb2")
    root = getattr(module, message_name).DESCRIPTOR.file
    out = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(file) -> None:
        for dep in file.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        file.CopyToProto(out.file.add())

    add(root)
    return out.SerializeToString(deterministic=True)


def _json_schema(properties: dict, required: list[str]) -> bytes:
    schema = {"type": "object", "properties": properties, "required": required}
    return json.dumps(schema, sort_keys=True, separators=(",", ":")).encode()


COMMAND_SCHEMA = _json_schema(
    {
        "step": {
            "type": "integer",
            "minimum": 0,
            "description": "physics step the command takes effect at",
        },
        "kind": {"type": "string", "enum": list(COMMAND_ARGS)},
        "args": {
            "type": "object",
            "description": "kind-specific arguments (joint, q, v, name, value, key; for an "
            "event, what a task or client said: kind, body, message, data)",
        },
    },
    ["step", "kind", "args"],
)
EVENT_SCHEMA = _json_schema(
    {
        "step": {"type": "integer", "minimum": 0},
        "t_ns": {"type": "integer", "minimum": 0},
        "kind": {"type": "string"},
        "body": {"type": "string", "description": "scene object the event concerns, or empty"},
        "message": {"type": "string"},
        "data": {"type": "object"},
    },
    ["step", "t_ns", "kind", "body", "message", "data"],
)
STRING_SCHEMA = _json_schema({"data": {"type": "string"}}, ["data"])


@dataclass(frozen=True)
class ChannelSpec:
    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str

    def schema_data(self) -> bytes:
        if self.schema_name.startswith("twin.") and self.schema_encoding == "protobuf":
            return blocks_descriptor_set()
        if self.schema_name.startswith("foxglove."):
            return foxglove_descriptor_set(self.schema_name.removeprefix("foxglove."))
        return {
            "twin.Command": COMMAND_SCHEMA,
            "twin.Event": EVENT_SCHEMA,
            "std_msgs/String": STRING_SCHEMA,
        }[self.schema_name]


JOINTS = ChannelSpec("/twin/joints", "twin.JointBlock", "protobuf", "protobuf")
SUCTION = ChannelSpec("/twin/suction", "twin.SuctionBlock", "protobuf", "protobuf")
POSES = ChannelSpec("/twin/poses", "twin.PoseBlock", "protobuf", "protobuf")
TF = ChannelSpec("/tf", "foxglove.FrameTransforms", "protobuf", "protobuf")
LOG = ChannelSpec("/events", "foxglove.Log", "protobuf", "protobuf")
EVENTS = ChannelSpec("/twin/events", "twin.Event", "jsonschema", "json")
COMMANDS = ChannelSpec("/commands", "twin.Command", "jsonschema", "json")
ROBOT_DESCRIPTION = ChannelSpec("/robot_description", "std_msgs/String", "jsonschema", "json")

# registration order fixes the schema and channel ids in every file
CHANNELS = (ROBOT_DESCRIPTION, JOINTS, SUCTION, POSES, TF, LOG, EVENTS, COMMANDS)

# A camera's channels, registered after CHANNELS for each of the configuration's cameras (a
# recording without cameras has none): its pictures and, with each one, its calibration (Foxglove
# projects with it).
IMAGE_SCHEMA, CALIBRATION_SCHEMA = "foxglove.CompressedImage", "foxglove.CameraCalibration"


def image_channel(camera: str) -> ChannelSpec:
    return ChannelSpec(f"/camera/{camera}/image", IMAGE_SCHEMA, "protobuf", "protobuf")


def calibration_channel(camera: str) -> ChannelSpec:
    return ChannelSpec(f"/camera/{camera}/calibration", CALIBRATION_SCHEMA, "protobuf", "protobuf")


# block message -> its channel's topic, in model.fields' block order
BLOCK_TOPICS = {
    block: next(c.topic for c in CHANNELS if c.schema_name == f"twin.{block}") for block in F.BLOCKS
}

# metadata record names
META_CONFIG = "twin.config"
META_RUN = "twin.run"
META_VERSIONS = "twin.versions"
META_RECOVERED = "twin.recovered"
LIBRARY = "twin-record 1"  # fixed: identical runs give byte-identical files

# The largest message twin writes (the writer refuses more, the readers refuse more): a 0.25 s block
# at the finest time step (2,500 frames) of 100 objects' poses is 14 MB; a URDF is far smaller.
MAX_MESSAGE_BYTES = 16 * 1024 * 1024
# Steps and simulated nanoseconds stay below these, so step * dt_ns fits an int64 at any time step.
MAX_STEP = 10**10
MAX_T_NS = 2**62
