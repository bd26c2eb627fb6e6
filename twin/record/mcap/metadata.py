"""The metadata records a recording starts with: configuration, run, engine, recording layout,
versions and machine — strings only, sorted, and no wall-clock time (identical runs give identical
files; the machine record differs only between machines or their floating-point settings)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import platform
import sys
from functools import cache
from importlib import metadata as importlib_metadata
from pathlib import Path

from twin.model.config import TwinConfig
from twin.model.errors import ConfigError, RecordingError
from twin.model.json_values import MAX_DEPTH, nesting_depth, shown
from twin.record.machine import machine
from twin.record.mcap import schemas as S
from twin.record.mcap import strict_json

RUN_SOURCES = ("task", "teleop", "remote")


def _dumps(value: object) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


@cache  # a package's version, read once per process (importlib.metadata parses its METADATA)
def _version(dist: str) -> str:
    try:
        return importlib_metadata.version(dist)
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


def versions(engine: dict[str, str] | None = None) -> dict[str, str]:
    """The packages' versions; engine: what the simulation says of itself
    (sim.world.engine_versions)."""
    api = (engine or {}).get("pybullet_api", "unknown")
    return {
        "twin": _version("twin"),
        "pybullet": _version("pybullet"),
        "pybullet_api": api,
        "numpy": _version("numpy"),
        "mcap": _version("mcap"),
        "protobuf": _version("protobuf"),
        "python": platform.python_version(),
        "platform": f"{sys.platform} {platform.machine()}",
    }


def portable_config(config: TwinConfig, recording: str | Path | None) -> TwinConfig:
    """config as a recording at `recording` stores it: a user URDF by its path relative to the
    recording's folder (no absolute path in the file: the same run recorded in two checkouts gives
    the same bytes, and a golden checks from any working directory or clone)."""
    urdf = config.profile.urdf_path
    if not urdf or recording is None or not Path(urdf).is_absolute():
        return config
    folder = Path(os.path.abspath(recording)).parent
    relative = Path(os.path.relpath(urdf, folder)).as_posix()
    return dataclasses.replace(
        config, profile=dataclasses.replace(config.profile, urdf_path=relative)
    )


def located_config(config: TwinConfig, recording: str | Path) -> TwinConfig:
    """The inverse of portable_config on reading: a relative URDF path resolved from the recording's
    folder."""
    urdf = config.profile.urdf_path
    if not urdf or Path(urdf).is_absolute():
        return config
    absolute = os.path.normpath(Path(os.path.abspath(recording)).parent / urdf)
    return dataclasses.replace(
        config, profile=dataclasses.replace(config.profile, urdf_path=absolute)
    )


def check_run(run: dict) -> dict:
    """The run description, validated: source, task name or path, JSON-safe parameters, and when
    present the task file's sha256 and which recording this run replays ({"file", "sha256"})."""
    if not isinstance(run, dict) or run.get("source") not in RUN_SOURCES:
        raise ConfigError(
            f"run description {run!r:.200} is invalid; expected source one of {RUN_SOURCES}"
        )
    params = run.get("params", {})
    # a reader refuses deeper (a recursion in every JSON tool)
    if nesting_depth(params) > MAX_DEPTH:
        raise ConfigError(
            f"run parameters nest lists and objects more than {MAX_DEPTH} levels deep; expected "
            f"at most {MAX_DEPTH}"
        )
    try:
        _dumps(params)
    except (TypeError, ValueError, RecursionError) as err:
        raise ConfigError(f"run parameters {params!r:.200} are not JSON data: {err}") from err
    out = {"source": run["source"], "task": str(run.get("task", "")), "params": params}
    if run.get("task_sha256"):
        out["task_sha256"] = str(run["task_sha256"])
    if isinstance(run.get("replay_of"), dict):
        out["replay_of"] = {str(k): str(v) for k, v in run["replay_of"].items()}
    if run.get("timeout_s") is not None:
        out["timeout_s"] = float(run["timeout_s"])
    return out


def run_metadata(
    config: TwinConfig,
    run: dict,
    recording: dict[str, str],
    engine_versions: dict[str, str] | None = None,
) -> dict[str, dict[str, str]]:
    """Metadata records by name, in the order they are written; engine_versions as versions() takes
    it."""
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
        S.META_RUN: {
            "source": run["source"],
            "task": run["task"],
            "params": _dumps(run["params"]),
            **({"task_sha256": run["task_sha256"]} if "task_sha256" in run else {}),
            **({"replay_of": _dumps(run["replay_of"])} if "replay_of" in run else {}),
            **({"timeout_s": repr(run["timeout_s"])} if "timeout_s" in run else {}),
        },
        "twin.engine": engine,
        S.META_RECORDING: dict(sorted(layout.items())),
        S.META_VERSIONS: dict(sorted(versions(engine_versions).items())),
        S.META_MACHINE: machine(),
    }


def parse_config(records: dict[str, dict[str, str]], where: str) -> TwinConfig:
    """The TwinConfig stored in a file's metadata; RecordingError naming the file if absent or
    bad."""
    record = records.get(S.META_CONFIG)
    if record is None or "json" not in record:
        raise RecordingError(f"{where} has no {S.META_CONFIG} metadata; it was not written by twin")
    try:
        # the schema names a NaN
        return TwinConfig.from_dict(strict_json.loads(record["json"], constants=True))
    except (ValueError, ConfigError) as err:
        raise RecordingError(f"{where}: its twin configuration is unreadable: {err}") from err


def parse_run(records: dict[str, dict[str, str]], where: str = "the recording") -> dict:
    """The run description of a file's metadata (empty fields if it has none); RecordingError naming
    the field if its source or parameters are malformed (a task is re-run with them)."""
    record = records.get(S.META_RUN, {})
    try:
        params = strict_json.loads(record.get("params", "{}"))
    except ValueError as err:
        raise RecordingError(f"{where}: {S.META_RUN} field params is not JSON: {err}") from err
    if not isinstance(params, dict):
        raise RecordingError(
            f"{where}: {S.META_RUN} field params = {shown(params)} is invalid; expected "
            f"a JSON object"
        )
    if nesting_depth(params) > MAX_DEPTH:  # never printed: repr recurses too
        raise RecordingError(
            f"{where}: {S.META_RUN} field params nests more than {MAX_DEPTH} levels deep; expected "
            f"at most {MAX_DEPTH}"
        )
    if S.META_RUN in records and record.get("source") not in RUN_SOURCES:
        raise RecordingError(
            f"{where}: {S.META_RUN} field source = {record.get('source')!r:.60} is invalid; "
            f"expected one of {', '.join(RUN_SOURCES)}"
        )
    run = {"source": record.get("source", ""), "task": record.get("task", ""), "params": params}
    if record.get("task_sha256"):
        run["task_sha256"] = record["task_sha256"]
    if record.get("replay_of"):
        try:
            replay_of = strict_json.loads(record["replay_of"])
        except ValueError:  # also nested too deep
            replay_of = None
        if isinstance(replay_of, dict):
            run["replay_of"] = replay_of
    if record.get("timeout_s"):
        try:
            timeout_s = float(record["timeout_s"])
        except ValueError:
            timeout_s = math.nan
        if not math.isfinite(timeout_s) or timeout_s <= 0:
            raise RecordingError(
                f"{where}: {S.META_RUN} field timeout_s = {record['timeout_s']!r:.60} is invalid; "
                "expected seconds > 0"
            )
        run["timeout_s"] = timeout_s
    return run
