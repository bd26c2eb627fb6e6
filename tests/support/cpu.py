"""The CPU time a process and everything it started have used, for tests that a server idles."""

from __future__ import annotations

import time

import psutil


def tree_cpu_s(pid: int) -> dict[int, float]:
    """{pid: user + system CPU seconds} of `pid` and its living descendants."""
    root = psutil.Process(pid)
    used = {}
    for proc in (root, *root.children(recursive=True)):
        try:
            times = proc.cpu_times()
        except psutil.NoSuchProcess:
            continue
        used[proc.pid] = times.user + times.system
    return used


def tree_cpu_over_s(pid: int, wall_s: float) -> float:
    """CPU seconds `pid` and its descendants use over the next wall_s seconds (a descendant that
    starts meanwhile counts whole)."""
    before = tree_cpu_s(pid)
    time.sleep(wall_s)
    after = tree_cpu_s(pid)
    return sum(cpu - before.get(p, 0.0) for p, cpu in after.items())
