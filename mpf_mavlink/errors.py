"""Errors the CLI reports as one clear line (no traceback)."""

from __future__ import annotations


class MpfError(Exception):
    """A known, user-facing failure; ``str(err)`` is one line naming the culprit."""


class ConfigError(MpfError):
    """A configuration value (file, key, path definition) is invalid."""
