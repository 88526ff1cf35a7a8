"""The package's layers, read from the source (every import, including those inside functions):

- ``core`` (so3, frames, paths, target, target estimator, guidance law and checks, adapter) is
  the pure guidance core: it may use ``errors``, ``constants`` and ``quaternion``, never the
  configuration
  (``config.scenario`` builds the core's objects from it, one layer up), the MAVLink boundary,
  the live bridge, run output, the CLI or ``sim``;
- the benchmarks (top-level ``bench/``, run by scripts/bench) and the laboratory (top-level
  ``lab/``: the firmware rigs, the soak, the profiles' identification) are tooling, not
  product: nothing that ships (``mpf_mavlink``, ``sim``: pyproject's packages) imports them,
  and they are no package the wheel holds;
- ``mavlink`` is the only package that imports pymavlink, and it knows nothing of guidance;
- ``quaternion`` (the one quaternion <-> matrix conversion of each kind) and ``constants`` are
  leaves that import nothing of ours, so that the core and the MAVLink boundary share them;
- ``runs`` (run directories, plots, verdicts, the replay's result) sits below the live bridge:
  the bridge writes runs, runs never imports the bridge (the replay, which drives the bridge's
  controller, is ``bridge.replay``);
- no two modules import each other, directly or round a longer circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "mpf_mavlink"


def _module(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """module -> the mpf_mavlink modules (or packages) it imports, and 'pymavlink' if it does."""
    graph: dict[str, set[str]] = {}
    for path in PKG.rglob("*.py"):
        mod = _module(path)
        is_pkg = path.name == "__init__.py"
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    here = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    here = here[: len(here) - (node.level - 1)]
                    base = ".".join(here + ([base] if base else []))
                # `from pkg import mod` imports the module pkg.mod when there is one
                names = [base] + [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for n in names:
                if n.split(".")[0] == "pymavlink":
                    found.add("pymavlink")
                elif n.startswith("mpf_mavlink"):
                    found.add(n)
        graph[mod] = found
    modules = set(graph)
    # keep the names that are modules or packages of ours (drop `from m import function`)
    return {
        m: {n for n in deps if n in modules or n == "pymavlink"} - {m} for m, deps in graph.items()
    }


GRAPH = _imports()


def _in(mod: str, *packages: str) -> bool:
    return any(mod == f"mpf_mavlink.{p}" or mod.startswith(f"mpf_mavlink.{p}.") for p in packages)


def test_the_layout_is_there():
    # the packages the README's map names; a move that drops one should fail here first
    for p in (
        "core",
        "core.guidance",
        "core.paths",
        "mavlink",
        "bridge",
        "runs",
        "config",
        "cli",
    ):
        assert f"mpf_mavlink.{p}" in GRAPH, p
    assert len([m for m in GRAPH if _in(m, "core")]) >= 10


def _top_level_imports(path: Path) -> set[str]:
    """The first component of every absolute import in ``path`` (those inside functions too)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module.split(".")[0])
    return out


def test_what_ships_never_imports_the_tooling_and_the_wheel_leaves_it_out():
    assert (ROOT / "bench" / "main.py").is_file() and (
        ROOT / "lab" / "rigs" / "common.py"
    ).is_file()
    assert not (PKG / "bench").exists()
    for path in [*PKG.rglob("*.py"), *(ROOT / "sim").rglob("*.py")]:
        assert not {"bench", "lab"} & _top_level_imports(path), path.relative_to(ROOT)
    # setuptools' own discovery with pyproject's include list: what the wheel packages
    import tomllib

    from setuptools import find_packages

    find = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    shipped = find_packages(str(ROOT), include=find["packages"]["find"]["include"])
    assert "mpf_mavlink" in shipped and "sim" in shipped
    assert not [p for p in shipped if p.split(".")[0] in ("bench", "lab", "tests", "scripts")], (
        shipped
    )


def test_core_is_pure_of_io_layers():
    for mod, deps in GRAPH.items():
        if _in(mod, "core"):
            # constants: the one home of physical constants, a leaf with no imports of its own
            bad = {d for d in deps if not (_in(d, "core", "errors", "constants", "quaternion"))}
            assert not bad, f"{mod} imports {sorted(bad)}"


def test_only_the_mavlink_package_touches_pymavlink_and_it_knows_no_guidance():
    for mod, deps in GRAPH.items():
        if "pymavlink" in deps:
            assert _in(mod, "mavlink"), f"{mod} imports pymavlink"
        if _in(mod, "mavlink"):
            bad = {d for d in deps - {"pymavlink"} if not _in(d, "mavlink", "errors", "quaternion")}
            assert not bad, f"{mod} imports {sorted(bad)}"


def test_the_leaves_import_nothing_of_ours():
    for leaf in ("mpf_mavlink.quaternion", "mpf_mavlink.constants"):
        assert leaf in GRAPH and not GRAPH[leaf], (leaf, GRAPH.get(leaf))


def test_runs_never_imports_the_bridge():
    assert "mpf_mavlink.bridge.replay" in GRAPH and "mpf_mavlink.runs.replay_result" in GRAPH
    for mod, deps in GRAPH.items():
        if _in(mod, "runs"):
            bad = {d for d in deps if _in(d, "bridge", "cli")}
            assert not bad, f"{mod} imports {sorted(bad)}"


def test_no_import_circle():
    # depth-first search for a back edge; a package's __init__ importing its own submodules is
    # how a package is built, so the edges from a submodule to its own package are not counted
    def edges(m: str) -> set[str]:
        return {d for d in GRAPH[m] - {"pymavlink"} if not m.startswith(d + ".")}

    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for d in sorted(edges(m)):
            if state.get(d) == 1:
                circle = stack[stack.index(d) :] + [d]
                raise AssertionError("import circle: " + " -> ".join(circle))
            if d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(GRAPH):
        if m not in state:
            visit(m)
