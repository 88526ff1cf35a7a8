"""Arguments and helpers the commands share (``run``, ``replay``): the ``--set`` override,
the run directory's default name, ``--no-plots`` / ``--quiet``, and typed number arguments that
fail in argparse's one line naming the option."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

#: the exit codes of each command (its --help lists them); a flight that ran to its end exits 0
#: (verdict PASS), 5 (FAIL) or 6 (NOT JUDGED: too short for its steady window)
EXIT_CODES = {
    "check": "0 every check passed (warnings allowed); 2 bad configuration; 3 a check failed",
    "sim": "0 flown, verdict PASS; 2 bad configuration / arguments / output directory; 3 refused "
    "by the pre-flight checks (--force flies it); 4 a safety exit of the bridge (SIL); 5 verdict "
    "FAIL; 6 verdict NOT JUDGED (the flight is shorter than its steady window); 130 Ctrl-C",
    "plot": "0 figures drawn; 2 not a run directory",
    "run": "0 flown and handed back, verdict PASS; 2 bad configuration / URL / no vehicle; 3 a "
    "pre-flight check failed (no mode request was sent); 4 a safety exit (telemetry or target "
    "lost, pilot took over, mode refused, hand-back not confirmed, the envelope monitor's hold "
    "policy handed back); 5 verdict FAIL; 6 verdict "
    "NOT JUDGED (shorter than its steady window); 130 Ctrl-C; 143 SIGTERM",
    "vehicle": "0 stopped (--duration reached, Ctrl-C or SIGTERM); 2 bad configuration / "
    "--serve URL (unknown scheme, unresolvable host, port in use) / arguments",
    "campaign": "0 every flight ran to its end (whatever its figures or verdict); 1 some "
    "flights errored or timed out; 2 bad campaign file / arguments / no scheduler; 130 Ctrl-C",
    "certify": "0 every flight ran to its end (whatever its verdict: the certificate's "
    "P(FAIL)); 1 some flights errored or timed out; 2 bad configuration / conditions / "
    "arguments / no scheduler; 130 Ctrl-C",
    "compare": "0 every flight ran to its end (a FAIL or NOT JUDGED verdict is a result: the "
    "table's verdict column); 2 bad configuration / arguments, or a flight could not run to its "
    "end (a safety exit, no flight recorded); 130 Ctrl-C",
}


def figure_lines(
    metrics: dict[str, Any], rows: list[tuple[str, str, str]], label_w: int, value_w: int
) -> list[str]:
    """A summary table's lines: label, value (4 significant digits; "n/a" when missing), unit."""
    lines = []
    for k, label, unit in rows:
        v = metrics.get(k)
        val = "n/a" if v is None else (f"{v:.4g}" if isinstance(v, float) else str(v))
        lines.append(f"{label:<{label_w}} {val:>{value_w}}  {unit}")
    return lines


def exit_codes_epilog(command: str) -> str:
    """``exit codes: ...`` for a command's --help."""
    import textwrap

    return textwrap.fill(f"exit codes: {EXIT_CODES[command]}.", 95)


def check_host(url: str, option: str) -> None:
    """A network MAVLink URL's host must resolve: an unresolvable one would fail every send
    (and stall each on the resolver) instead of failing once. MpfError names the option."""
    import socket

    from mpf_mavlink.errors import MpfError
    from mpf_mavlink.mavlink.url import parse_url

    parsed = parse_url(url)  # MpfError (one line) for anything malformed
    if parsed.kind == "serial":
        return
    try:
        socket.getaddrinfo(parsed.host, parsed.port)
    except (OSError, UnicodeError) as e:
        why = getattr(e, "strerror", None) or str(e)
        raise MpfError(f"{option} {url}: cannot resolve host {parsed.host!r} ({why})") from None


def add_overrides(p: argparse.ArgumentParser, example: str) -> None:
    """``--set KEY=VALUE`` (repeatable) into ``args.overrides``; ``example`` shows a key or two."""
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help=f"override one configuration key, e.g. {example} (repeatable; validated like "
        "the file)",
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


_N = TypeVar("_N", int, float)


def _parsed(text: str, conv: Callable[[str], _N], what: str) -> _N:
    """conv(text), or an argparse error saying the text is not ``what``."""
    try:
        return conv(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None


def positive(text: str) -> float:
    """argparse type: a number > 0."""
    v = _parsed(text, float, "a number")
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def seconds(text: str) -> float:
    """argparse type: a number of seconds >= 0."""
    v = _parsed(text, float, "a number of seconds")
    if not v >= 0.0:
        raise argparse.ArgumentTypeError(f"must be >= 0 s, got {text}")
    return v


def count(text: str) -> int:
    """argparse type: a whole number >= 0."""
    v = _parsed(text, int, "a whole number")
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v
