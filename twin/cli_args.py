"""Argument types shared by the `twin` subcommands: each refuses bad text with one clear line."""

from __future__ import annotations

import argparse
from collections.abc import Callable


def whole_number(minimum: int = 1) -> Callable[[str], int]:
    """An argparse type: an integer >= minimum."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= {minimum}")
        return value

    return parse


def port(*, allow_any: bool = False) -> Callable[[str], int]:
    """An argparse type: a TCP port 1..65535, or 0 (any free port) when allow_any."""
    lowest = 0 if allow_any else 1

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if not lowest <= value <= 65535:
            expected = "0..65535 (0: any free port)" if allow_any else "a whole number 1..65535"
            raise argparse.ArgumentTypeError(f"port {text!r} is invalid; expected {expected}")
        return value

    return parse
