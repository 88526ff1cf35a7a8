"""The guidance core is pure: no I/O, no clock, no pymavlink (the I/O boundary of style.md)."""

import ast
from pathlib import Path

PURE = [
    "mpf_mavlink/core/so3.py",
    "mpf_mavlink/core/frames.py",
    "mpf_mavlink/core/paths/base.py",
    "mpf_mavlink/core/paths/shapes.py",
    "mpf_mavlink/core/target.py",
    "mpf_mavlink/core/target_filter.py",
    "mpf_mavlink/core/guidance/law.py",
    "mpf_mavlink/core/guidance/checks.py",
    "mpf_mavlink/core/adapter.py",
    "mpf_mavlink/core/energy.py",
]
FORBIDDEN = {
    "socket",
    "time",
    "pymavlink",
    "serial",
    "select",
    "threading",
    "asyncio",
    "subprocess",
    "os",
}


def test_pure_modules_import_no_io():
    root = Path(__file__).resolve().parents[1]
    for rel in PURE:
        tree = ast.parse((root / rel).read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for n in names:
                assert n.split(".")[0] not in FORBIDDEN, f"{rel} imports {n}"
