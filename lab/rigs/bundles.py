"""Where the SITL firmware bundles are, and their unpacked copies in the git-ignored cache.

The bundles (``../shared/sitl/*.tar.xz``: PX4 v1.16.0 SIH, ArduPlane 4.7-dev) are test equipment
beside the repository, never inside it. :func:`sitl_dir` finds them (``MPF_SITL_DIR``, else
``shared/sitl`` beside the checkout or beside one of its parents: a worktree under ``wt/`` finds
the same directory as the main checkout); :func:`unpack` extracts a tarball once into
``.cache/sitl/<name>/`` under the repository root (``.gitignore``: ``/.cache/``).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tarfile
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
CACHE = ROOT / ".cache" / "sitl"
TARBALLS = {"px4": "px4-sitl-v1.16.0-sih.tar.xz", "arduplane": "arduplane-sitl-4.7dev.tar.xz"}
# the file that proves a directory is an unpacked bundle of that autopilot
ENTRY = {"px4": "px4-sih-airplane", "arduplane": "bin/arduplane"}


class RigError(Exception):
    """A one-line refusal naming the culprit (the rig prints it and exits 2)."""


def sitl_dir() -> Path | None:
    """The directory holding the bundles, or None (a bare clone)."""
    env = os.environ.get("MPF_SITL_DIR")
    if env:
        return Path(env).expanduser().resolve()
    for base in (ROOT.parent, ROOT.parent.parent):
        d = base / "shared" / "sitl"
        if d.is_dir():
            return d
    return None


def why_missing(autopilot: str) -> str | None:
    """None when the default bundle of ``autopilot`` is there; else why not, in one line."""
    d = sitl_dir()
    if d is None:
        return (
            "no SITL bundles: neither MPF_SITL_DIR nor ../shared/sitl beside the checkout "
            "(README 'Flying PX4 SITL' / 'Flying ArduPilot SITL')"
        )
    if not (d / TARBALLS[autopilot]).is_file():
        return f"{d / TARBALLS[autopilot]}: no such bundle"
    return None


def check_bundle(autopilot: str, spec: str | None) -> Path:
    """Validate ``--bundle`` (a directory or a .tar.xz; None: the default) without unpacking."""
    if spec is None:
        why = why_missing(autopilot)
        if why is not None:
            raise RigError(f"--bundle not given and {why}")
        d = sitl_dir()
        assert d is not None
        return d / TARBALLS[autopilot]
    p = Path(spec).expanduser().resolve()
    if p.is_dir():
        if not (p / ENTRY[autopilot]).is_file():
            raise RigError(f"--bundle {spec}: not a {autopilot} bundle (no {ENTRY[autopilot]})")
        return p
    if p.is_file():
        if not tarfile.is_tarfile(p):
            raise RigError(f"--bundle {spec}: neither a directory nor a tar archive")
        return p
    raise RigError(f"--bundle {spec}: no such file or directory")


def _extract(tf: tarfile.TarFile, dest: Path, bundle: Path) -> None:
    """Every member of ``tf`` under ``dest``, none outside it: tarfile's "tar" filter where the
    interpreter has it (Python 3.11.4 and later), else a stricter refusal checked here (an
    absolute name, a ``..`` component, a link that leaves the archive, a device)."""
    if hasattr(tarfile, "tar_filter"):
        tf.extractall(dest, filter="tar")
        return
    root = dest.resolve()
    for m in tf.getmembers():
        target = (root / m.name).resolve()
        bad = m.name.startswith("/") or not target.is_relative_to(root) or m.isdev()
        if m.issym() or m.islnk():
            base = target.parent if m.issym() else root
            bad = bad or not (base / m.linkname).resolve().is_relative_to(root)
        if bad:
            raise RigError(f"--bundle {bundle}: member {m.name!r} would land outside the cache")
    tf.extractall(dest)  # noqa: S202 - every member checked above


def unpack(autopilot: str, bundle: Path) -> Path:
    """The bundle's directory: ``bundle`` itself, or its tarball unpacked into the cache (once;
    into a temporary directory renamed into place, so an interrupted unpack leaves no half)."""
    if bundle.is_dir():
        return bundle
    name = bundle.name.split(".tar")[0]
    dest = CACHE / name
    if (dest / ENTRY[autopilot]).is_file() and dest.stat().st_mtime >= bundle.stat().st_mtime:
        return dest
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=CACHE))
    try:
        with tarfile.open(bundle) as tf:
            _extract(tf, tmp, bundle)
        inner = tmp / name if (tmp / name).is_dir() else tmp
        if not (inner / ENTRY[autopilot]).is_file():
            raise RigError(f"--bundle {bundle}: not a {autopilot} bundle (no {ENTRY[autopilot]})")
        old = None
        if dest.exists():  # an older unpack of the same name: the rig's own cache entry
            old = Path(tempfile.mkdtemp(prefix=f".{name}-old-", dir=CACHE))
            dest.rename(old / name)
        inner.rename(dest)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return dest


def bundle_version(d: Path) -> str:
    """The first line of the bundle's RUN.txt (what it is)."""
    run = d / "RUN.txt"
    if not run.is_file():
        return d.name
    return run.read_text(errors="replace").splitlines()[0].split(",")[0].strip()


def die_with_parent() -> None:
    """``preexec_fn`` of the rig's children (firmware, bridge): SIGTERM when the rig dies, even
    by SIGKILL or a test's timeout, so that no SITL keeps flying (and holding its ports)."""
    import ctypes

    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except OSError:  # not glibc Linux: the rig's own clean-up still stops them
        pass


def stop_process_group(proc: subprocess.Popen[Any] | None, term_wait_s: float) -> None:
    """Stops a firmware started in its own process group: SIGTERM, ``term_wait_s`` s to exit,
    then SIGKILL."""
    if proc is not None and proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(term_wait_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)
