"""Build the optional compiled hot paths: ``python -m mpf_mavlink._build [--if-stale]``.

Compiles the modules of :data:`mpf_mavlink._compiled.MODULES` with Cython (pure-Python mode:
the .py is the source, its .pxd adds the C types) into ``mpf_mavlink/_ext/`` and writes the
manifest the import hook checks (see :mod:`mpf_mavlink._compiled`). Without Cython or a C
compiler it says so in one line and exits 0: everything then runs as pure Python.
``--if-stale`` builds only when a source, Cython's version or the flags changed.
``--annotate DIR`` also writes Cython's HTML annotation of each module (white lines are C).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from mpf_mavlink._compiled import (
    EXT_DIR,
    EXT_SUFFIX,
    MANIFEST,
    MODULES,
    PACKAGE_DIR,
    ext_file,
    read_manifest,
    source_digest,
    source_files,
)

#: -ffp-contract=off: no fused multiply-add, so that each product and sum rounds as Python's
#: do and the compiled modules give the pure ones' floats bit for bit.
CFLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math"]
#: The .pxd files carry the C types; the annotations are for mypy (``x: float`` would
#: otherwise also become a C double and ``bool`` a Python object check).
DIRECTIVES = {"language_level": 3, "annotation_typing": False, "binding": True}


def _wanted(cython_version: str) -> dict[str, Any]:
    return {
        "cython": cython_version,
        "cflags": CFLAGS,
        "directives": DIRECTIVES,
        "modules": {n: {"file": ext_file(n).name, "sha256": source_digest(n)} for n in MODULES},
    }


def up_to_date(want: dict[str, Any]) -> bool:
    """True when the build on disk is of these sources, this Cython and these flags."""
    have = read_manifest()
    if have is None or any(have.get(k) != want[k] for k in ("cython", "cflags", "modules")):
        return False
    return all(ext_file(n).is_file() for n in MODULES)


def build(annotate: Path | None = None, jobs: int = 2) -> dict[str, Any]:
    """Compile every module into EXT_DIR and write the manifest; returns it. The generated C
    and the objects stay in EXT_DIR/.build, so that a rebuild after an edit re-generates and
    re-compiles only the modules whose .py or .pxd changed."""
    from Cython.Build import cythonize
    from Cython.Shadow import __version__ as cython_version  # what Cython.__version__ is
    from setuptools import Distribution, Extension
    from setuptools.command.build_ext import build_ext

    want = _wanted(cython_version)
    root = PACKAGE_DIR.parent
    work = EXT_DIR / ".build"
    exts = [
        Extension(name, [str(source_files(name)[0].relative_to(root))], extra_compile_args=CFLAGS)
        for name in MODULES
    ]
    cwd = os.getcwd()
    os.chdir(root)  # cythonize finds each .pxd beside its .py, by the package path
    try:
        modules = cythonize(
            exts,
            compiler_directives=dict(DIRECTIVES),
            build_dir=str(work / "c"),
            annotate=annotate is not None,
            quiet=True,
            force=annotate is not None,
            nthreads=jobs,
        )
        cmd = build_ext(Distribution({"name": "mpf-mavlink-hotpaths", "ext_modules": modules}))
        cmd.build_lib = str(work / "lib")
        cmd.build_temp = str(work / "obj")
        cmd.parallel = jobs
        cmd.ensure_finalized()
        cmd.run()
    finally:
        os.chdir(cwd)
    if annotate is not None:
        annotate.mkdir(parents=True, exist_ok=True)
        for html in (work / "c").rglob("*.html"):
            shutil.copy(html, annotate / html.name)
    (EXT_DIR / MANIFEST).unlink(missing_ok=True)  # no manifest while the files change
    for name in MODULES:
        *package, leaf = name.split(".")
        dst = ext_file(name)
        shutil.copy(work.joinpath("lib", *package, leaf + EXT_SUFFIX), dst.with_suffix(".tmp"))
        os.replace(dst.with_suffix(".tmp"), dst)
    (EXT_DIR / ".gitignore").write_text("*\n")
    tmp_manifest = EXT_DIR / (MANIFEST + ".tmp")
    tmp_manifest.write_text(json.dumps(want, indent=1) + "\n")
    os.replace(tmp_manifest, EXT_DIR / MANIFEST)
    return want


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m mpf_mavlink._build", description=__doc__)
    p.add_argument("--if-stale", action="store_true", help="build only when out of date")
    p.add_argument("--annotate", type=Path, help="write Cython's HTML annotations here")
    args = p.parse_args(argv)
    try:
        from Cython.Shadow import __version__ as cython_version
    except ImportError:
        print("[build] compiled hot paths: skipped (no Cython): pure Python", file=sys.stderr)
        return 0
    if args.if_stale and args.annotate is None and up_to_date(_wanted(cython_version)):
        return 0
    t0 = time.perf_counter()
    try:
        build(args.annotate)
    except Exception as exc:  # no compiler, no Python.h: the pure modules still run
        print(
            f"[build] compiled hot paths: not built ({type(exc).__name__}: {exc}): pure Python",
            file=sys.stderr,
        )
        return 0
    print(
        f"[build] compiled hot paths: {len(MODULES)} modules in "
        f"{time.perf_counter() - t0:.1f} s ({EXT_DIR})",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
