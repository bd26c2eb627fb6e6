"""The metadata records a recording starts with: configuration, run, engine, recording layout and
versions — strings only, sorted, and no wall-clock time (identical runs give identical files)."""

from __future__ import annotations

import json
import platform
import sys
from importlib import metadata as importlib_metadata

from twin.config import TwinConfig
from twin.errors import ConfigError, RecordingError
from twin.record import schemas as S

RUN_SOURCES = ("task", "teleop", "remote")


def _dumps(value: object) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _version(dist: str) -> str:
    try:
        return importlib_metadata.version(dist)
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


def versions() -> dict[str, str]:
    from twin.world import pybullet_version

    return {
        "twin": _version("twin"), "pybullet": _version("pybullet"), "pybullet_api": pybullet_version(),
        "numpy": _version("numpy"), "mcap": _version("mcap"), "protobuf": _version("protobuf"),
        "python": platform.python_version(), "platform": f"{sys.platform} {platform.machine()}",
    }


def check_run(run: dict) -> dict:
    """The run description, validated: source, task name or path, JSON-safe parameters."""
    if not isinstance(run, dict) or run.get("source") not in RUN_SOURCES:
        raise ConfigError(f"run description {run!r} is invalid; expected source one of {RUN_SOURCES}")
    params = run.get("params", {})
    try:
        _dumps(params)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"run parameters {params!r} are not JSON data: {err}") from err
    return {"source": run["source"], "task": str(run.get("task", "")), "params": params}


def run_metadata(config: TwinConfig, run: dict, recording: dict[str, str]) -> dict[str, dict[str, str]]:
    """Metadata records by name, in the order they are written."""
    run = check_run(run)
    engine = {k: _dumps(v) for k, v in sorted(config.to_dict()["engine"].items())}
    engine["dt_ns"] = str(config.dt_ns)
    layout = {
        "joint_names": _dumps(list(config.profile.joint_names)),
        "object_names": _dumps([o.name for o in config.objects]),
        **recording,
    }
    return {
        S.META_CONFIG: {"json": _dumps(config.to_dict())},
        S.META_RUN: {"source": run["source"], "task": run["task"], "params": _dumps(run["params"])},
        "twin.engine": engine,
        S.META_RECORDING: dict(sorted(layout.items())),
        S.META_VERSIONS: dict(sorted(versions().items())),
    }


def parse_config(records: dict[str, dict[str, str]], where: str) -> TwinConfig:
    """The TwinConfig stored in a file's metadata; RecordingError naming the file if absent or bad."""
    record = records.get(S.META_CONFIG)
    if record is None or "json" not in record:
        raise RecordingError(f"{where} has no {S.META_CONFIG} metadata; it was not written by twin")
    try:
        return TwinConfig.from_dict(json.loads(record["json"]))
    except (ValueError, ConfigError) as err:
        raise RecordingError(f"{where}: its twin configuration is unreadable: {err}") from err


def parse_run(records: dict[str, dict[str, str]]) -> dict:
    record = records.get(S.META_RUN, {})
    try:
        params = json.loads(record.get("params", "{}"))
    except ValueError:
        params = {}
    return {"source": record.get("source", ""), "task": record.get("task", ""), "params": params}
