"""`twin view --web` started with SIGINT ignored (a script's background job: the shell ignores it,
and Python keeps it so) still ends on Ctrl-C, as `twin serve` does, with its viewer process gone."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[2]


def test_view_web_started_with_sigint_ignored_ends_on_ctrl_c(tmp_path):
    env = {**os.environ, "HOME": str(tmp_path), "TMPDIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    golden = ROOT / "recordings" / "pick_place_mtb.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", "view", str(golden), "--web"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),  # noqa: PLW1509
        start_new_session=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)
        line = proc.stdout.readline() if ready else ""
        assert "serving the web viewer at" in line, (line, proc.poll())
        viewer = psutil.Process(proc.pid).children(recursive=True)
        assert viewer
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)  # to twin alone, as a Ctrl-C reaches it
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 130, err
        assert time.monotonic() - t0 < 10
        time.sleep(0.5)
        assert not [p for p in viewer if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
