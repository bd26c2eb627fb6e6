"""Every /commands message of a real file satisfies the JSON Schema that the file itself carries,
and that schema names exactly the command kinds the Twin applies (a new kind cannot be forgotten
there)."""

from __future__ import annotations

import json

from mcap.reader import make_reader

from twin.sim.twin import Twin


def _schema_and_commands(path) -> tuple[dict, list[dict]]:
    """Read with the mcap package's own reader, not ours."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        commands, schema = [], None
        for sch, _channel, message in reader.iter_messages(topics=["/commands"]):
            schema = json.loads(sch.data)
            commands.append(json.loads(message.data))
    return schema, commands


def test_the_command_schema_names_every_kind_the_twin_applies(pick_place_mcap):
    schema, _ = _schema_and_commands(pick_place_mcap[0])
    assert set(schema["properties"]["kind"]["enum"]) == set(Twin._COMMANDS)


def test_every_recorded_command_satisfies_the_files_own_schema(pick_place_mcap):
    schema, commands = _schema_and_commands(pick_place_mcap[0])
    kinds = {c["kind"] for c in commands}
    # what the task said, what it moved, the pad
    assert {"event", "joint_target", "signal"} <= kinds
    props = schema["properties"]
    for c in commands:
        assert set(schema["required"]) <= set(c)
        assert isinstance(c["step"], int) and c["step"] >= props["step"]["minimum"]
        assert c["kind"] in props["kind"]["enum"] and isinstance(c["args"], dict)
