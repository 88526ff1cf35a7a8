"""Suite-wide pytest hooks."""

from __future__ import annotations

from typing import Any

import pytest


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[Any]) -> None:
    """Make ``--dist loadgroup`` (scripts/test) honour ``xdist_group`` marks under pytest 9.

    pytest-xdist 3.8 groups tests by appending ``@group`` to ``item._nodeid`` on the worker;
    pytest 9 builds ``nodeid`` from ``item._id`` instead, so the suffix is lost and grouped
    tests (the real-firmware flights of one autopilot, the soak pairs) spread over workers and
    fly at once. Done here the same way on ``_id`` when xdist's own suffix is missing."""
    if not getattr(config.option, "loadgroup", False):
        return
    try:
        from _pytest.nodeid import coerce_node_id
    except ImportError:  # pytest < 9: xdist's own suffix works
        return
    for item in items:
        if "@" in item.nodeid.rsplit("]", 1)[-1]:
            continue  # xdist did it
        names = sorted(
            {str(m.args[0] if m.args else m.kwargs.get("name", "default"))
             for m in item.iter_markers("xdist_group")}
        )  # fmt: skip
        if names:
            item._id = coerce_node_id(f"{item.nodeid}@{'_'.join(names)}")
