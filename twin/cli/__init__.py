"""The `twin` command: argument parsing and printing only, one module per command family."""

import os

# Before numpy loads: a command's numpy work is small arrays, so OpenBLAS's pool of threads only
# costs its start, 0.1-0.17 s of CPU per command and per worker process (measured: `twin info`
# ten times, 5.7-5.9 s CPU with the pool, 4.0-4.9 s without). A value the user set is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from twin.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
