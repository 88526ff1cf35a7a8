"""Errors that the CLI reports as one clear line (no traceback) with a non-zero exit."""

from __future__ import annotations


class MpfError(Exception):
    """A known, user-facing failure. ``str(err)`` is one line naming the culprit."""

    exit_code = 2


class ConfigError(MpfError):
    """A configuration value (file, key, path definition) is invalid."""


class CheckFailed(MpfError):
    """A pre-flight check (Assumption 1, gain condition, feasibility) failed."""

    exit_code = 3
