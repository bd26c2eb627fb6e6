"""Is there a Vulkan driver for Rerun's headless viewer to render with? Without one the viewer
starts, then fails with a bare "transport error"; the Vulkan loader's own search for driver
manifests (ICD files) tells before it starts. Linux only: elsewhere nothing is checked."""

from __future__ import annotations

import os
import sys
from pathlib import Path

INSTALL_HINT = (
    "the headless viewer renders with Vulkan; install a software driver: "
    "`sudo apt-get install mesa-vulkan-drivers` (Debian, Ubuntu; or run "
    "./tools/setup_test_system.sh)"
)
_SYSTEM_DIRS = ("/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d", "/usr/share/vulkan/icd.d")


def _manifest_dirs(env: dict) -> list[Path]:
    """Where the Vulkan loader looks for driver manifests on Linux (XDG dirs, then the system's)."""
    home = env.get("HOME", "")
    config = [env.get("XDG_CONFIG_HOME") or f"{home}/.config",
              *(env.get("XDG_CONFIG_DIRS") or "/etc/xdg").split(":")]
    data = [env.get("XDG_DATA_HOME") or f"{home}/.local/share",
            *(env.get("XDG_DATA_DIRS") or "/usr/local/share:/usr/share").split(":")]
    return [Path(d) / "vulkan" / "icd.d" for d in (*config, *data) if d] + [
        Path(d) for d in _SYSTEM_DIRS
    ]


def missing_driver(env: dict | None = None) -> str | None:
    """None when a Vulkan driver manifest is found (or on another system than Linux); else what is
    missing and the command that installs it, one line."""
    if not sys.platform.startswith("linux"):
        return None
    env = dict(os.environ) if env is None else env
    chosen = env.get("VK_DRIVER_FILES") or env.get("VK_ICD_FILENAMES")
    if chosen:  # the loader takes only these
        files = [Path(f) for f in chosen.split(":") if f]
        if any(f.is_file() or (f.is_dir() and any(f.glob("*.json"))) for f in files):
            return None
        return f"no Vulkan driver: VK_DRIVER_FILES/VK_ICD_FILENAMES names none that exists; " \
               f"{INSTALL_HINT}"
    for folder in _manifest_dirs(env):
        try:
            if any(folder.glob("*.json")):
                return None
        except OSError:
            continue
    return f"no Vulkan driver is installed (no manifest in /usr/share/vulkan/icd.d); {INSTALL_HINT}"
