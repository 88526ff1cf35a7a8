"""Optional compiled hot paths: load a module's Cython build only while it matches its .py.

The per-frame math (the law, the path evaluation, the prediction, the adapter) is written as
plain typed Python and runs as such everywhere. ``python -m mpf_mavlink._build`` (which
``scripts/_venv.sh`` runs when Cython and a C compiler are present) compiles those same .py
files, with the C types of their augmenting ``.pxd`` files beside them, into ``_ext/`` under
their dotted names, and records there the sha256 of each module's .py and .pxd. They are not
put beside the .py: Python's importer prefers an extension module to a .py of the same name in
the same folder, so an edited .py would silently lose to a stale build. Instead
:class:`CompiledFinder` (first on ``sys.meta_path``, installed by ``mpf_mavlink/__init__``)
loads a build only when the module's sources hash to what the manifest recorded; otherwise it
warns once and lets the ordinary importer load the .py.
Which processes use a build: the simulations (``mpf-mavlink sim``, ``campaign``, ``compare``:
:func:`prefer_for_simulation`) unless MPF_COMPILED=0, everything else only when asked with
MPF_COMPILED=1; MPF_PURE_PYTHON=1 overrides both. A simulation keeps the CPU busy, and there the
compiled modules run the controller's path in ~0.6 of the interpreter's time and the SIL's
lockstep loop faster (bench sil_real_time_factor); the live bridge sleeps between frames,
and there they measured no faster than the interpreter (bench bridge_latency_ms), so a live
flight runs the .py files unless asked.
The compiled and the pure modules compute the same IEEE double operations in the same order
(no fused multiply-add, ``-ffp-contract=off``), so their results agree bit for bit.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import json
import os
import sys
import sysconfig
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

#: The modules compiled when a build is possible, in dependency order.
MODULES: tuple[str, ...] = (
    "mpf_mavlink.core.guidance.law",
    "mpf_mavlink.core.paths.base",
    "mpf_mavlink.core.guidance.predict",
    "mpf_mavlink.core.adapter",
    "mpf_mavlink.core.target_filter",
    "mpf_mavlink.bridge.estimator",
)

PACKAGE_DIR = Path(__file__).resolve().parent
#: Where the builds and their manifest live (git-ignored); MPF_COMPILED_DIR overrides it.
EXT_DIR = Path(os.environ.get("MPF_COMPILED_DIR") or PACKAGE_DIR / "_ext")
MANIFEST = "manifest.json"
EXT_SUFFIX: str = sysconfig.get_config_var("EXT_SUFFIX") or ".so"


class StaleCompiledWarning(RuntimeWarning):
    """A compiled module no longer matches its .py or .pxd: the .py is used instead."""


def source_files(name: str) -> tuple[Path, Path]:
    """The .py and the augmenting .pxd of module ``name`` (mpf_mavlink.x.y)."""
    base = PACKAGE_DIR.joinpath(*name.split(".")[1:])
    return base.with_suffix(".py"), base.with_suffix(".pxd")


#: The .pxd the modules' own .pxd files cimport (C math with Python's results and errors).
SHARED_PXD = (PACKAGE_DIR / "_cmath.pxd",)


def source_digest(name: str) -> str:
    """sha256 of the module's .py, its .pxd (empty when absent) and the shared .pxd files:
    what a build is of."""
    h = hashlib.sha256()
    for f in (*source_files(name), *SHARED_PXD):
        h.update(f.read_bytes() if f.is_file() else b"")
        h.update(b"\0")
    return h.hexdigest()


def ext_file(name: str, ext_dir: Path = EXT_DIR) -> Path:
    """The build of module ``name`` for this interpreter."""
    return ext_dir / f"{name}{EXT_SUFFIX}"


def read_manifest(ext_dir: Path = EXT_DIR) -> dict[str, Any] | None:
    """The build's manifest, or None when there is no (readable) build."""
    try:
        data = json.loads((ext_dir / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


class CompiledLoader(importlib.machinery.ExtensionFileLoader):
    """Loads a build; one that cannot be loaded (a broken file, a missing symbol) warns once and
    the module runs from its .py instead: a build never turns into an import error."""

    def __init__(self, fullname: str, path: str, py: Path) -> None:
        super().__init__(fullname, path)
        self.py = py
        self.fallback: importlib.machinery.SourceFileLoader | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        try:
            return super().create_module(spec)
        except ImportError as exc:
            warnings.warn(
                f"mpf_mavlink: the compiled {spec.name} does not load ({exc}); using the .py",
                StaleCompiledWarning,
                stacklevel=2,
            )
            self.fallback = importlib.machinery.SourceFileLoader(spec.name, str(self.py))
            return ModuleType(spec.name)  # a plain module, which exec_module fills from the .py

    def exec_module(self, module: ModuleType) -> None:
        if self.fallback is None:
            super().exec_module(module)
            return
        module.__file__ = str(self.py)
        self.fallback.exec_module(module)


class CompiledFinder:
    """A meta path finder for the modules of a build's manifest (see the module docstring)."""

    def __init__(self, ext_dir: Path, digests: dict[str, str]) -> None:
        self.ext_dir = ext_dir
        self.digests = digests
        self.stale: list[str] = []

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        want = self.digests.get(fullname)
        if want is None:
            return None
        so = ext_file(fullname, self.ext_dir)
        if not so.is_file():
            return None  # built for another interpreter: the .py
        if source_digest(fullname) != want:
            self.stale.append(fullname)
            warnings.warn(
                f"mpf_mavlink: the compiled {fullname} is older than its source; using the .py "
                "(rebuild: python -m mpf_mavlink._build, or source scripts/_venv.sh)",
                StaleCompiledWarning,
                stacklevel=2,
            )
            return None
        loader = CompiledLoader(fullname, str(so), source_files(fullname)[0])
        return importlib.machinery.ModuleSpec(fullname, loader, origin=str(so))


def _asked() -> bool:
    return os.environ.get("MPF_COMPILED", "") == "1"


def prefer_for_simulation() -> CompiledFinder | None:
    """A simulation's default (module docstring): the build, unless MPF_COMPILED is set (0
    keeps pure Python) or MPF_PURE_PYTHON is. Sets MPF_COMPILED=1 in the environment, so the
    processes the simulation starts (a campaign's workers and their SIL flights) load the same.
    Call it before the hot modules are imported: one imported already stays as it is."""
    if "MPF_COMPILED" not in os.environ:
        os.environ["MPF_COMPILED"] = "1"
    return install()


def install() -> CompiledFinder | None:
    """Put a :class:`CompiledFinder` first on ``sys.meta_path`` when a build exists,
    MPF_COMPILED=1 asks for it and MPF_PURE_PYTHON is not set; None otherwise (everything then
    runs as pure Python)."""
    if os.environ.get("MPF_PURE_PYTHON", "") not in ("", "0") or not _asked():
        return None
    for f in sys.meta_path:
        if isinstance(f, CompiledFinder):
            return f
    manifest = read_manifest()
    if manifest is None:
        return None
    try:
        mods = manifest.get("modules", {})
        digests = {str(k): str(v["sha256"]) for k, v in mods.items() if k in MODULES}
    except (AttributeError, KeyError, TypeError):  # a manifest not of our build: pure Python
        return None
    finder = CompiledFinder(EXT_DIR, digests)
    sys.meta_path.insert(0, finder)
    return finder


def compiled_modules() -> list[str]:
    """The hot-path modules that run compiled in this process (importing them)."""
    import importlib

    out = []
    for name in MODULES:
        mod = importlib.import_module(name)
        if str(getattr(mod, "__file__", "")).endswith(EXT_SUFFIX):
            out.append(name)
    return out


def status() -> str:
    """One line for ``--version`` and the benchmarks: what runs compiled, or why nothing."""
    names = compiled_modules()
    if names:
        short = ", ".join(n.rsplit(".", 1)[1] for n in names)
        return f"compiled hot paths: {short}"
    if os.environ.get("MPF_PURE_PYTHON", "") not in ("", "0"):
        return "compiled hot paths: off (MPF_PURE_PYTHON), pure Python"
    if not _asked():
        built = "built" if read_manifest() is not None else "none built"
        return (
            f"compiled hot paths: {built}, not used (MPF_COMPILED=1 uses them; the "
            "simulations do unless MPF_COMPILED=0), pure Python"
        )
    if read_manifest() is None:
        return "compiled hot paths: none built (python -m mpf_mavlink._build), pure Python"
    return "compiled hot paths: stale or for another Python, pure Python"
