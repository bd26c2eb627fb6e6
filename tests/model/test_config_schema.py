"""The stored configuration's schema and the JSON and TOML files twin reads: every bad value, every
nesting depth and every degenerate camera is one ConfigError line, never a TypeError, RecursionError
or ZeroDivisionError traceback."""

from __future__ import annotations

import json
import math

import pytest

from twin.cli import main
from twin.model import config as C
from twin.model.config import TwinConfig, check_camera_view
from twin.model.errors import ConfigError
from twin.model.images import CAMERAS, CameraSpec
from twin.model.json_values import (
    MAX_DEPTH,
    all_finite,
    load_json_text,
    load_toml_text,
    nesting_depth,
    shown,
)

SCHEMAS = {
    "config": C.CONFIG_SCHEMA,
    "profile": C.PROFILE_SCHEMA,
    "object": C.OBJECT_SCHEMA,
    "engine": C.ENGINE_SCHEMA,
    "suction": C.SUCTION_SCHEMA,
    "camera": C.CAMERA_SCHEMA,
}
WRONG = (7, 1.5, "x", None, True, [7], [[7]], {"a": 1}, [], {})


@pytest.mark.parametrize("schema", sorted(SCHEMAS))
def test_every_field_kind_says_what_it_expects(schema):
    """expected() hashed a nested schema (a dict) or a list of one: a TypeError while wording the
    error."""
    for name, spec in SCHEMAS[schema].items():
        text = spec.expected()
        assert isinstance(text, str) and text and "kind" not in text, (schema, name, text)
    assert C.CONFIG_SCHEMA["objects"].expected() == "a list of at most 100 JSON objects"
    assert C.CONFIG_SCHEMA["profile"].expected() == "a JSON object"


@pytest.mark.parametrize("field", sorted(C.CONFIG_SCHEMA))
def test_a_wrong_value_in_each_field_is_a_config_error_naming_it(field):
    base = json.loads(json.dumps(TwinConfig().to_dict()))
    for bad in WRONG:
        data = {**base, field: bad}
        try:
            TwinConfig.from_dict(data)
        except ConfigError as err:
            assert field in str(err) and "\n" not in str(err), (field, bad, str(err))
    missing = {k: v for k, v in base.items() if k != field}
    if field in ("keymap", "cameras"):  # they default to none
        assert TwinConfig.from_dict(missing) == TwinConfig()
    else:
        with pytest.raises(ConfigError, match=f"field {field} is missing; expected "):
            TwinConfig.from_dict(missing)


def test_objects_7_names_the_field_and_what_it_should_be():
    data = {**json.loads(json.dumps(TwinConfig().to_dict())), "objects": 7}
    with pytest.raises(ConfigError) as err:
        TwinConfig.from_dict(data)
    assert str(err.value) == (
        "twin.config field objects = 7 is invalid; expected a list of at most 100 JSON objects"
    )


# -- nesting ---------------------------------------------------------------------------------------


def test_nesting_depth_and_all_finite_walk_without_recursion():
    deep = json.loads("[" * 900 + "1.5" + "]" * 900)
    assert nesting_depth(deep, 10_000) == 900 and nesting_depth(deep) == MAX_DEPTH + 1
    assert (
        nesting_depth(7) == 0
        and nesting_depth([]) == 1
        and nesting_depth({"a": [1, {"b": []}]}) == 4
    )
    assert (
        all_finite(deep)
        and not all_finite([deep, [math.nan]])
        and not all_finite({"a": {"b": -math.inf}})
    )
    assert shown(deep) == "(a value nested too deeply to show)" or shown(deep).startswith("[[[")


@pytest.mark.parametrize("depth", [MAX_DEPTH, MAX_DEPTH + 1, 900, 5000, 100_000])
def test_json_and_toml_text_nested_deeper_than_the_limit_is_one_line(depth):
    text = "[" * depth + "]" * depth
    if depth <= MAX_DEPTH:
        assert nesting_depth(load_json_text(text, "f")) == depth
    else:
        with pytest.raises(ConfigError) as err:
            load_json_text(text, "x.json cannot be read")
        assert str(err.value) == (
            f"x.json cannot be read: arrays or tables nest more than {MAX_DEPTH} levels "
            f"deep; twin reads at most {MAX_DEPTH}"
        )
    toml = "a = " + "[" * (depth - 1) + "]" * (depth - 1)  # the file itself is a table: one level
    if depth <= MAX_DEPTH:
        assert nesting_depth(load_toml_text(toml, "f")) == depth
    else:
        with pytest.raises(
            ConfigError,
            match=f"y.toml is not valid TOML: arrays or tables nest more than {MAX_DEPTH}",
        ):
            load_toml_text(toml, "y.toml is not valid TOML")
    inline = "a = " + "{b = " * depth + "1" + "}" * depth
    with pytest.raises(ConfigError, match="nest more than"):
        load_toml_text(inline, "z.toml")


def test_malformed_json_and_toml_are_one_line_naming_the_file():
    with pytest.raises(
        ConfigError, match=r"^k.json cannot be read: Expecting value: line 1 column 1 \(char 0\)$"
    ):
        load_json_text("", "k.json cannot be read")
    with pytest.raises(ConfigError, match=r"^k.json cannot be read: .*"):
        load_json_text(b"\xff\xfe\xfa", "k.json cannot be read")
    with pytest.raises(ConfigError, match=r"^s.toml: Invalid value \(at end of document\)$"):
        load_toml_text("a = ", "s.toml")


DEEP_FILES = {
    # name: text (5000 levels: a RecursionError in json and tomllib, a traceback before)
    "robot.toml": 'urdf = "r.urdf"\npad_link = "tool0"\nx = ' + "[" * 5000 + "]" * 5000 + "\n",
    "robot.json": '{"urdf": "r.urdf", "x": ' + "[" * 5000 + "]" * 5000 + "}",
    "keys.toml": "[keys]\na = " + "[" * 5000 + "]" * 5000 + "\n",
    "keys.json": '{"keys": {"a": ' + "[" * 5000 + "]" * 5000 + "}}",
    # parses: refused by the limit
    "keys_900.json": '{"keys": {"a": ' + "[" * 900 + "]" * 900 + "}}",
}


@pytest.mark.parametrize("name", sorted(DEEP_FILES))
def test_deeply_nested_profile_and_key_map_files_are_one_line_exit_2(tmp_path, capsys, name):
    path = tmp_path / name
    path.write_text(DEEP_FILES[name])
    argv = (
        ["run", "pick_place", "--robot", str(path), "--no-record"]
        if name.startswith("robot")
        else ["teleop", "--keymap", str(path), "--keys", "wait"]
    )
    assert main(argv) == 2
    _out, err = capsys.readouterr()
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("twin: error: "), err
    assert str(path) in err and f"arrays or tables nest more than {MAX_DEPTH} levels deep" in err, (
        err
    )
    assert len(err) < 300


# -- cameras ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "said"),
    [
        ({"eye_m": (0.0, 0.0, 1.0), "target_m": (0.0, 0.0, 1.0)}, "are 0 m apart"),
        (
            {"eye_m": (0.0, 0.0, 1.0), "target_m": (0.0, 0.0, 1.0 + 1e-9)},
            "m apart; expected a target at least",
        ),
        ({"up": (0.0, 0.0, 0.0)}, "up [0.0, 0.0, 0.0] is no direction"),
        ({"up": (1e-300, 0.0, 0.0)}, "is no direction"),
        (
            {"eye_m": (0.0, 0.0, 1.0), "target_m": (0.0, 0.0, 0.0), "up": (0.0, 0.0, 3.0)},
            "is along the view direction",
        ),
        (
            {"eye_m": (0.0, 0.0, 1.0), "target_m": (0.0, 0.0, 0.0), "up": (0.0, 1e-8, -1.0)},
            "is along the view",
        ),
    ],
)
def test_a_camera_that_cannot_look_anywhere_is_refused(change, said):
    camera = CameraSpec("c", **change)
    with pytest.raises(ConfigError, match="camera 'c': ") as err:
        TwinConfig(cameras=(camera,))
    assert said in str(err.value) and "\n" not in str(err.value)
    data = json.loads(json.dumps({**TwinConfig().to_dict(), "cameras": [camera.__dict__]}))
    with pytest.raises(ConfigError, match=said.replace("[", r"\[").replace("]", r"\]")):
        TwinConfig.from_dict(data)  # the schema path: a recording's twin.config


def test_the_built_in_cameras_and_near_degenerate_ones_pass():
    for camera in CAMERAS.values():
        check_camera_view(camera)
        check_camera_view(
            CameraSpec("p", mount="pad", eye_m=camera.eye_m, target_m=camera.target_m, up=camera.up)
        )
    check_camera_view(
        CameraSpec("c", eye_m=(0.0, 0.0, 1.0), target_m=(0.0, 0.0, 0.0), up=(0.0, 1e-3, 1.0))
    )
