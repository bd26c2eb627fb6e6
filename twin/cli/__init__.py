"""The `twin` command: argument parsing and printing only, one module per command family."""

from twin.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
