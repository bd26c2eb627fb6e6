"""`twin view --screenshot` without a Vulkan driver names what is missing and how to install it,
one line and exit 2, before the viewer starts (it used to fail with "transport error")."""

from __future__ import annotations

import os
import subprocess

from support.cli import TWIN

from twin.record.rerun import vulkan


def test_no_driver_manifest_anywhere_is_named_with_its_install_command(tmp_path, monkeypatch):
    env = {"HOME": str(tmp_path), "XDG_DATA_DIRS": str(tmp_path / "d"),
           "XDG_CONFIG_DIRS": str(tmp_path / "c")}
    monkeypatch.setattr(vulkan, "_SYSTEM_DIRS", (str(tmp_path / "none"),))
    missing = vulkan.missing_driver(env)
    assert missing is not None and "no Vulkan driver is installed" in missing
    assert "sudo apt-get install mesa-vulkan-drivers" in missing
    icd = tmp_path / "d" / "vulkan" / "icd.d"
    icd.mkdir(parents=True)
    (icd / "lvp_icd.x86_64.json").write_text("{}")
    assert vulkan.missing_driver(env) is None  # the loader's XDG search finds it


def test_screenshot_without_a_driver_is_one_line_and_no_picture(pick_place_cli, tmp_path):
    out = tmp_path / "shot.png"
    done = subprocess.run(
        [*TWIN, "view", str(pick_place_cli["mcap"]), "--screenshot", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "HOME": str(tmp_path),
             "VK_DRIVER_FILES": str(tmp_path / "missing_icd.json")},
        check=False,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no Vulkan driver" in lines[0], done.stderr
    assert "`sudo apt-get install mesa-vulkan-drivers`" in lines[0]
    assert not out.exists()
