"""The guidance core is pure: no I/O, no clock, no pymavlink (the I/O boundary of style.md)."""

import ast
from pathlib import Path

PURE = [
    "mpf_mavlink/so3.py",
    "mpf_mavlink/frames.py",
    "mpf_mavlink/paths/base.py",
    "mpf_mavlink/paths/shapes.py",
    "mpf_mavlink/target.py",
    "mpf_mavlink/target_filter.py",
    "mpf_mavlink/guidance/law.py",
    "mpf_mavlink/guidance/checks.py",
    "mpf_mavlink/adapter.py",
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
