"""Arguments and helpers the commands share (``run``, ``replay``): the ``--set`` override,
the run directory's default name, ``--no-plots`` / ``--quiet``, and typed number arguments that
fail in argparse's one line naming the option."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path


def add_overrides(p: argparse.ArgumentParser, example: str) -> None:
    """``--set KEY=VALUE`` (repeatable) into ``args.overrides``; ``example`` shows a key or two."""
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help=f"override one configuration key, e.g. {example} (repeatable; validated like the file)",
    )  # fmt: skip


def add_output_flags(p: argparse.ArgumentParser, plots_help: str, quiet_help: str) -> None:
    """``--no-plots`` and ``-q/--quiet``."""
    p.add_argument("--no-plots", action="store_true", help=plots_help)
    p.add_argument("-q", "--quiet", action="store_true", help=quiet_help)


def default_out(kind: str, name: str) -> Path:
    """The default run directory: ``runs/<local time>-<kind>-<config name>``."""
    return Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{kind}-{name}"


def printer(quiet: bool) -> Callable[[str], None]:
    """The progress log: print and flush, or nothing with ``--quiet``."""
    if quiet:
        return lambda s: None
    return lambda s: print(s, flush=True)


def positive(text: str) -> float:
    """argparse type: a number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def seconds(text: str) -> float:
    """argparse type: a number of seconds >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not v >= 0.0:
        raise argparse.ArgumentTypeError(f"must be >= 0 s, got {text}")
    return v


def count(text: str) -> int:
    """argparse type: a whole number >= 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v
