"""The optional compiled hot paths (mpf_mavlink._compiled): the same floats as pure Python, bit
for bit, and a build that no longer matches its source is never used.

The compiled modules are the .py files themselves with C doubles from their .pxd, built with
-ffp-contract=off: the same IEEE operations in the same order, so every result must be
identical, not merely close. The comparison runs the probe (tests/_compiled_probe.py) in two
processes, one with MPF_PURE_PYTHON=1. Without a build (no Cython or no C compiler: scripts/
_venv.sh builds one otherwise) there is nothing compiled to compare and those tests skip.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from mpf_mavlink import _compiled
from mpf_mavlink._compiled import (
    EXT_DIR,
    EXT_SUFFIX,
    MANIFEST,
    MODULES,
    CompiledFinder,
    StaleCompiledWarning,
    read_manifest,
    source_digest,
)

ROOT = Path(__file__).resolve().parents[1]
PROBE = Path(__file__).resolve().parent / "_compiled_probe.py"
LAW = "mpf_mavlink.core.guidance.law"

needs_build = pytest.mark.skipif(
    read_manifest() is None,
    reason="no compiled build (python -m mpf_mavlink._build needs Cython and a C compiler)",
)


def _probe(env: dict[str, str], *args: str) -> dict[str, list[str]]:
    r = subprocess.run(
        [sys.executable, str(PROBE), *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, **env},
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    out: dict[str, list[str]] = json.loads(r.stdout)
    return out


def _first_difference(a: list[str], b: list[str]) -> str:
    for i, (x, y) in enumerate(zip(a, b, strict=False)):
        if x != y:
            return f"item {i}: compiled {x} pure {y}"
    return f"lengths {len(a)} and {len(b)}"


@needs_build
@pytest.mark.slow
def test_compiled_and_pure_give_the_same_floats_bit_for_bit() -> None:
    """The law (diagnostics, errors record, every extension), the path, the prediction, the
    controller over the real ArduPlane tlog (estimator, prediction, law, adapter), the
    estimator alone over that tlog's samples (and spoiled copies it must refuse), the live
    target's filter on a radio feed, math at and past its domain (the same floats, or the
    same exception) and the 300 s paper scenario."""
    pure = _probe({"MPF_PURE_PYTHON": "1"})
    comp = _probe({"MPF_PURE_PYTHON": "0", "MPF_COMPILED": "1"})
    assert pure["compiled"] == []
    assert comp["compiled"] == list(MODULES), "the build exists but was not loaded"
    # the probe exercised something: floats of 160 law states, of the tlog's steps, and the
    # paper scenario's steady RMS with a digest of each of its columns
    for part, least in (
        ("law", 10000), ("controller", 10000), ("target_filter", 10000), ("estimator", 10000),
        ("domain", 18), ("paper", 20),
    ):  # fmt: skip
        assert len(pure[part]) >= least, part
        assert comp[part] == pure[part], f"{part}: {_first_difference(comp[part], pure[part])}"


def test_a_stale_build_is_not_loaded(tmp_path: Path) -> None:
    """A manifest digest that does not match the .py: the finder declines (the ordinary
    importer then loads the .py) and warns; a matching one loads the build."""
    so = tmp_path / f"{LAW}{EXT_SUFFIX}"
    so.write_bytes(b"not loaded here")
    stale = CompiledFinder(tmp_path, {LAW: "0" * 64})
    with pytest.warns(StaleCompiledWarning, match="older than its source"):
        assert stale.find_spec(LAW) is None
    assert stale.stale == [LAW]
    current = CompiledFinder(tmp_path, {LAW: source_digest(LAW)})
    spec = current.find_spec(LAW)
    assert spec is not None and spec.origin == str(so)
    assert current.find_spec("mpf_mavlink.core.frames") is None  # not in the manifest
    so.unlink()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert current.find_spec(LAW) is None  # no build for this interpreter: the .py


def test_the_digest_covers_the_pxd(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Editing a module's .pxd (its C types) makes its build stale as editing the .py does."""
    pkg = tmp_path / "core" / "guidance"
    pkg.mkdir(parents=True)
    (pkg / "law.py").write_text("x = 1\n")
    monkeypatch.setattr(_compiled, "PACKAGE_DIR", tmp_path)
    before = source_digest(LAW)
    (pkg / "law.pxd").write_text("cdef double x\n")
    with_pxd = source_digest(LAW)
    (pkg / "law.py").write_text("x = 2\n")
    assert len({before, with_pxd, source_digest(LAW)}) == 3


def _with_build(ext: Path, code: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter that asks for the compiled modules of build ``ext``."""
    env = {**os.environ, "MPF_COMPILED_DIR": str(ext), "MPF_PURE_PYTHON": "0", "MPF_COMPILED": "1"}
    return subprocess.run(
        [sys.executable, "-W", "default", "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )


@needs_build
def test_an_edited_source_falls_back_to_the_py_with_one_warning(tmp_path: Path) -> None:
    """End to end in a fresh interpreter: a copy of the build whose manifest records another
    digest for the law (as after an edit of law.py) runs the law from its .py, says so once,
    and still loads the other compiled modules."""
    ext = tmp_path / "ext"
    shutil.copytree(EXT_DIR, ext, ignore=shutil.ignore_patterns(".build"))
    manifest = json.loads((ext / MANIFEST).read_text())
    manifest["modules"][LAW]["sha256"] = "0" * 64
    (ext / MANIFEST).write_text(json.dumps(manifest))
    code = (
        "import mpf_mavlink.core.guidance.law as law, mpf_mavlink.core.paths.base as b;"
        "print(law.__file__); print(b.__file__)"
    )
    r = _with_build(ext, code)
    assert r.returncode == 0, r.stderr
    law_file, base_file = r.stdout.split()
    assert law_file.endswith("law.py")
    assert base_file.endswith(EXT_SUFFIX) and base_file.startswith(str(ext))
    assert r.stderr.count("StaleCompiledWarning") == 1, r.stderr


@needs_build
def test_a_build_that_does_not_load_falls_back_to_the_py(tmp_path: Path) -> None:
    """A current manifest but a broken file (truncated, foreign): the .py runs, said once."""
    ext = tmp_path / "ext"
    shutil.copytree(EXT_DIR, ext, ignore=shutil.ignore_patterns(".build"))
    (ext / f"{LAW}{EXT_SUFFIX}").write_bytes(b"\x7fELF broken")
    code = (
        "import mpf_mavlink.core.guidance.law as law;"
        "print(law.__file__); print(law.steady_state_frame(1.0, 0.5, 16.0)[0])"
    )
    r = _with_build(ext, code)
    assert r.returncode == 0, r.stderr
    law_file, wd11 = r.stdout.split()
    assert law_file.endswith("law.py")
    assert float(wd11) == math.sqrt(1.0 - (1.0 / 16.0) ** 2 - (0.5 / 16.0) ** 2)  # (15)
    assert r.stderr.count("does not load") == 1, r.stderr


def test_pure_python_when_asked() -> None:
    """MPF_PURE_PYTHON=1: no finder, every module from its .py, and --version says so."""
    r = subprocess.run(
        [sys.executable, "-m", "mpf_mavlink.cli.main", "--version"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "MPF_PURE_PYTHON": "1"},
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert "pure Python" in r.stdout and "MPF_PURE_PYTHON" in r.stdout


def test_a_manifest_not_of_our_build_means_pure_python(monkeypatch: pytest.MonkeyPatch) -> None:
    # install() runs at every import of mpf_mavlink: a damaged manifest must not break it
    monkeypatch.setattr(
        sys, "meta_path", [f for f in sys.meta_path if not isinstance(f, CompiledFinder)]
    )
    monkeypatch.delenv("MPF_PURE_PYTHON", raising=False)
    monkeypatch.setenv("MPF_COMPILED", "1")
    for bad in ({"modules": {LAW: 1}}, {"modules": {LAW: {}}}, {"modules": [LAW]}):
        monkeypatch.setattr(_compiled, "read_manifest", lambda bad=bad: bad)
        assert _compiled.install() is None
    assert not any(isinstance(f, CompiledFinder) for f in sys.meta_path)


def test_outside_the_simulations_the_build_is_used_only_when_asked() -> None:
    """Without MPF_COMPILED=1 every module runs from its .py (the live bridge's default), and
    --version says how to ask."""
    env = {k: v for k, v in os.environ.items() if k not in ("MPF_COMPILED", "MPF_PURE_PYTHON")}
    code = "import mpf_mavlink.core.guidance.law as law, sys; print(law.__file__)"
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith("law.py")
    r = subprocess.run(
        [sys.executable, "-m", "mpf_mavlink.cli.main", "--version"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )
    assert r.returncode == 0 and "MPF_COMPILED=1" in r.stdout, r.stdout + r.stderr


def _sim_then_law_file(env: dict[str, str], out: Path) -> tuple[str, str]:
    """A short kinematic ``mpf-mavlink sim`` in a fresh interpreter; (where the law it flew was
    loaded from, MPF_COMPILED as the processes it starts see it)."""
    code = (
        "import os, sys; from mpf_mavlink.cli.main import main;"
        "rc = main(['sim', 'configs/paper_lemniscate.yaml', '-q', '--no-plots', '--out', "
        f"{str(out)!r}, '--set', 'sim.duration_s=2']);"
        "import mpf_mavlink.core.guidance.law as law;"
        "print(law.__file__, os.environ.get('MPF_COMPILED', '-'))"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300
    )
    assert r.returncode == 0, r.stderr[-2000:]
    law_file, asked = r.stdout.split()[-2:]
    return law_file, asked


@needs_build
def test_the_simulations_fly_the_build_unless_told_not_to(tmp_path: Path) -> None:
    """``mpf-mavlink sim`` (and campaign, compare: prefer_for_simulation) loads the build when
    nothing is set, and passes the choice on to the processes it starts; MPF_COMPILED=0 and
    MPF_PURE_PYTHON=1 keep it pure."""
    env = {k: v for k, v in os.environ.items() if k not in ("MPF_COMPILED", "MPF_PURE_PYTHON")}
    law_file, asked = _sim_then_law_file(env, tmp_path / "a")
    assert law_file.endswith(EXT_SUFFIX) and asked == "1", (law_file, asked)
    law_file, asked = _sim_then_law_file({**env, "MPF_COMPILED": "0"}, tmp_path / "b")
    assert law_file.endswith("law.py") and asked == "0", (law_file, asked)
    law_file, _ = _sim_then_law_file({**env, "MPF_PURE_PYTHON": "1"}, tmp_path / "c")
    assert law_file.endswith("law.py"), law_file
