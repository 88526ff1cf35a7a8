"""Command line: ``mpf-mavlink COMMAND`` (:data:`COMMANDS`; each defined in its module).

Library first, CLI thin: each command parses, calls a library function, reports. Known
errors (MpfError) print one line and exit non-zero; nothing else is caught.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Any

from mpf_mavlink import __version__
from mpf_mavlink.errors import MpfError


class _OneLineErrors(argparse.ArgumentParser):
    """Command-line errors as one line naming the culprit, like every other error of the CLI
    (argparse prints the whole usage first). Sub-commands inherit the class."""

    def error(self, message: str) -> Any:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _Version(argparse.Action):
    """--version: the version."""

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        print(f"{parser.prog} {__version__}")
        parser.exit(0)


#: every sub-command, in the order of the help, and where its parser is defined
COMMANDS = {
    "check": ("mpf_mavlink.cli.parsers", "add_check_parser"),
    "sim": ("mpf_mavlink.cli.parsers", "add_sim_parser"),
    "plot": ("mpf_mavlink.cli.parsers", "add_plot_parser"),
    "run": ("mpf_mavlink.cli.run", "add_run_parser"),
    "replay": ("mpf_mavlink.cli.parsers", "add_replay_parser"),
    "vehicle": ("mpf_mavlink.cli.parsers", "add_vehicle_parser"),
    "campaign": ("mpf_mavlink.cli.parsers", "add_campaign_parser"),
    "certify": ("mpf_mavlink.cli.parsers", "add_certify_parser"),
    "compare": ("mpf_mavlink.cli.parsers", "add_compare_parser"),
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command line; ``only``: with that sub-command alone (what ``main`` builds when the
    command is named first, so that a command loads no other's definitions)."""
    p = _OneLineErrors(
        prog="mpf-mavlink",
        description="3D moving-path-following guidance for fixed-wing vehicles over MAVLink.",
    )
    p.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module, adder) in COMMANDS.items():
        if only is None or name == only:
            getattr(importlib.import_module(module), adder)(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    parser = build_parser(words[0] if words and words[0] in COMMANDS else None)
    args = parser.parse_args(words)
    try:
        return int(args.func(args))
    except MpfError as e:
        _leave_nothing_behind()
        print(f"mpf-mavlink: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        _leave_nothing_behind()
        print("mpf-mavlink: interrupted", file=sys.stderr)
        return 130


def _leave_nothing_behind() -> None:
    """A failed command removes the run directories it created and left empty."""
    from mpf_mavlink.runs.rundir import remove_empty_created

    remove_empty_created()


if __name__ == "__main__":
    sys.exit(main())
