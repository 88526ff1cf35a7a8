#!/usr/bin/env python3
"""The house's figures (issue 44), printed as JSON: source lines, what ``mpf-mavlink run`` loads,
long classes and functions, ``Any`` in signatures and the imports that run back up a layer.

    .venv/bin/python scripts/house_figures.py [--root TREE] [--fly] [--mypy]

``--root`` measures another checkout (default: this one); ``--fly`` flies ``mpf-mavlink run``
for a few seconds against ``mpf-mavlink vehicle --serve`` (the checkout's own .venv, run
directory in a temporary directory) and counts the modules of ``mpf_mavlink/`` and ``sim/`` it
had loaded at exit, imports inside functions included; without it the closure is that of the
modules ``run`` imports before it connects. ``--mypy`` adds the count of ``mypy --strict
mpf_mavlink`` errors per file (a minute of CPU).
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parents[1]
SHIPPED = ("mpf_mavlink", "sim")  # pyproject's packages: what the wheel holds
TOOLING = ("bench", "lab")  # top-level packages beside them: benchmarks, rigs, soak, calibration
#: The layers, bottom first: a module may import its own layer and those below. ``bench`` and
#: ``lab`` are tooling beside the product (above everything they measure or fly).
LAYERS = [
    ("mpf_mavlink.errors", "mpf_mavlink.constants"),
    ("mpf_mavlink.core",),
    ("mpf_mavlink.mavlink",),
    ("mpf_mavlink.config",),
    ("mpf_mavlink.runs",),
    ("mpf_mavlink.bridge",),
    ("sim",),
    ("mpf_mavlink.campaign",),
    ("mpf_mavlink.cli",),
    ("mpf_mavlink.bench", "bench", "lab"),
]
LONG_CLASS, LONG_FUNCTION = 250, 80


def _sources(root: Path) -> list[Path]:
    return sorted(p for top in SHIPPED for p in (root / top).rglob("*.py"))


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines())


def _module(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(mod: str) -> int | None:
    for i, names in enumerate(LAYERS):
        if any(mod == n or mod.startswith(n + ".") for n in names):
            return i
    return None


def source_lines(root: Path) -> dict[str, Any]:
    per: Counter[str] = Counter()
    for p in _sources(root):
        rel = p.relative_to(root).parts
        per["/".join(rel[:2]) if len(rel) > 2 else rel[0]] += _lines(p)
    total = sum(per.values())
    by_top = {t: sum(n for k, n in per.items() if k.split("/")[0] == t) for t in SHIPPED}
    bench = root / "mpf_mavlink" / "bench"
    return {
        "total": total,
        "modules": len(_sources(root)),
        **by_top,
        "of_which_mpf_mavlink/bench": per.get("mpf_mavlink/bench", 0) if bench.is_dir() else 0,
        "largest_packages": dict(per.most_common(8)),
        # beside the product, not shipped (counted so that a move out of the wheel shows)
        "tooling_not_shipped": {
            t: sum(_lines(f) for f in (root / t).rglob("*.py"))
            for t in TOOLING
            if (root / t).is_dir()
        },
    }


def long_definitions(root: Path) -> dict[str, Any]:
    classes, functions = [], []
    any_in_signatures: Counter[str] = Counter()
    for p in _sources(root):
        rel = str(p.relative_to(root))
        top = p.relative_to(root).parts[0]
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if isinstance(node, ast.ClassDef) and n > LONG_CLASS:
                    classes.append(f"{rel}:{node.name} {n}")
                elif not isinstance(node, ast.ClassDef) and n > LONG_FUNCTION:
                    functions.append(f"{rel}:{node.name} {n}")
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                a = node.args
                anns = [x.annotation for x in [*a.posonlyargs, *a.args, *a.kwonlyargs]]
                anns += [a.vararg.annotation if a.vararg else None]
                anns += [a.kwarg.annotation if a.kwarg else None, node.returns]
                for ann in anns:
                    if ann is not None:
                        any_in_signatures[top] += len(re.findall(r"\bAny\b", ast.unparse(ann)))
    return {
        f"classes_over_{LONG_CLASS}": sorted(classes, key=lambda s: -int(s.split()[-1])),
        f"functions_over_{LONG_FUNCTION}": sorted(functions, key=lambda s: -int(s.split()[-1])),
        "Any_in_signatures": dict(any_in_signatures),
    }


def _imports(root: Path, path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import of ours in ``path``, those inside functions too."""
    mod = _module(root, path).split(".")
    here = mod if path.name == "__init__.py" else mod[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = here[: len(here) - (node.level - 1)]
                base = ".".join(up + ([base] if base else []))
            out.append((node.lineno, base))
    return [(ln, m) for ln, m in out if m.split(".")[0] in (*SHIPPED, *TOOLING)]


def arrows_back_up(root: Path) -> dict[str, Any]:
    """Imports from a module to a module of a higher layer (:data:`LAYERS`), by package pair."""
    pairs: Counter[str] = Counter()
    where: list[str] = []
    for p in _sources(root):
        src = _module(root, p)
        a = _layer(src)
        for ln, dst in _imports(root, p):
            b = _layer(dst)
            if a is not None and b is not None and b > a:
                pairs[f"{LAYERS[a][0]} -> {LAYERS[b][0]}"] += 1
                where.append(f"{p.relative_to(root)}:{ln} {dst}")
    return {"count": sum(pairs.values()), "pairs": dict(pairs), "where": where}


_DUMP = """
import atexit, json, sys
def _dump():
    with open({out!r}, "w") as f:
        ours = [m for m in list(sys.modules) if m.split(".")[0] in ("mpf_mavlink", "sim")]
        json.dump(sorted(ours), f)
atexit.register(_dump)
{body}
"""


def _closure(root: Path, python: str, body: str, env: dict[str, str]) -> list[str]:
    with tempfile.TemporaryDirectory(prefix="house-") as d:
        out = Path(d) / "modules.json"
        code = _DUMP.format(out=str(out), body=body.replace("@DIR@", d))
        r = subprocess.run([python, "-c", code], cwd=root, env=env, capture_output=True, text=True)
        if not out.is_file():
            raise SystemExit(f"closure: the process wrote nothing (rc {r.returncode}): {r.stderr}")
        mods: list[str] = json.loads(out.read_text())
        return mods


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_closure(root: Path, fly: bool) -> dict[str, Any]:
    python = str(root / ".venv" / "bin" / "python")
    env = dict(os.environ)
    cfg = "configs/default.yaml"
    if not fly:
        # what `mpf-mavlink run` has imported when it starts the bridge (cli/run.py: cmd_run)
        body = (
            "import sys\nfrom mpf_mavlink.cli.main import build_parser\nbuild_parser('run')\n"
            "import mpf_mavlink.cli.run, mpf_mavlink.bridge.live, mpf_mavlink.config.schema\n"
            "import mpf_mavlink.runs.rundir"
        )
        mods = _closure(root, python, body, env)
    else:
        port = _free_port()
        veh = subprocess.Popen(
            [python, "-m", "mpf_mavlink.cli", "vehicle", cfg, "--serve",
             f"udpin:127.0.0.1:{port}", "--duration", "120"],
            cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            assert veh.stdout is not None
            veh.stdout.readline()  # printed once the vehicle serves
            body = (
                "import sys\nfrom mpf_mavlink.cli.main import main\n"
                f"rc = main(['run', {cfg!r}, '--connect', 'udpout:127.0.0.1:{port}',"
                " '--duration', '8', '--out', '@DIR@/run'])\n"
                "print('rc', rc)"
            )
            mods = _closure(root, python, body, env)
        finally:
            veh.terminate()
            veh.wait(10)
    files = []
    for m in mods:
        base = root / Path(*m.split("."))
        f = base / "__init__.py" if (base / "__init__.py").is_file() else base.with_suffix(".py")
        if f.is_file():
            files.append(f)
    return {
        "how": "flown 8 s against the SIL vehicle" if fly else "imports before connecting",
        "modules": len(files),
        "lines": sum(_lines(f) for f in files),
    }


def mypy_strict(root: Path) -> dict[str, Any]:
    r = subprocess.run(
        [str(root / ".venv" / "bin" / "python"), "-m", "mypy", "--strict", "mpf_mavlink"],
        cwd=root, capture_output=True, text=True,
    )  # fmt: skip
    per: Counter[str] = Counter()
    for line in r.stdout.splitlines():
        if ": error:" in line:
            per[line.split(":", 1)[0]] += 1
    return {"errors": sum(per.values()), "per_file": dict(per.most_common())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="scripts/house_figures.py", description=__doc__)
    p.add_argument("--root", type=Path, default=HERE, help="the checkout to measure")
    p.add_argument("--fly", action="store_true", help="fly `run` for the import closure")
    p.add_argument("--mypy", action="store_true", help="count mypy --strict errors")
    a = p.parse_args(argv)
    root = a.root.resolve()
    out: dict[str, Any] = {
        "root": str(root),
        "source_lines": source_lines(root),
        "run_import_closure": run_closure(root, a.fly),
        **long_definitions(root),
        "arrows_back_up": arrows_back_up(root),
    }
    if a.mypy:
        out["mypy_strict"] = mypy_strict(root)
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
