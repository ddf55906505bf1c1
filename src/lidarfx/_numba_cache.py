"""Keep numba's on-disk kernel cache in step with the package's sources.

numba caches a compiled ``@njit(cache=True)`` function beside its source file and
checks only that file's timestamp: a kernel that calls (and inlines) a function of
*another* module keeps its old machine code when only the callee changes (a documented
limitation, numba issue #1833).  lidarfx's kernels call across modules (the feature
engine calls ``plane.write_plane``, ``eigen.eigh3`` …), so an edited checkout or an
editable install could silently compute with stale code.

:func:`check` fingerprints every ``.py`` file of the package (path, size, mtime) and, when
the fingerprint differs from the one recorded at the last check, deletes the package's
numba cache files (``__pycache__/*.nbi``, ``*.nbc``) before any kernel loads.  A fresh
install has no cache yet, so this costs nothing there; an unwritable install is left as it
is (its files do not change without a reinstall, which numba notices).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent
STAMP = ROOT / "__pycache__" / "lidarfx-numba-sources.key"


def fingerprint(root: Path = ROOT) -> str:
    """Hash of (relative path, size, mtime) of every ``.py`` file under ``root``."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        st = p.stat()
        h.update(f"{p.relative_to(root)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def check(root: Path = ROOT, stamp: Path | None = None) -> bool:
    """Delete stale numba cache files under ``root``; True when the sources changed."""
    stamp = STAMP if stamp is None else stamp
    try:
        key = fingerprint(root)
        if stamp.exists() and stamp.read_text() == key:
            return False
        for pattern in ("*.nbi", "*.nbc"):
            for f in root.rglob(f"__pycache__/{pattern}"):
                try:
                    f.unlink()
                except FileNotFoundError:  # another process cleared it first
                    pass
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(key)
        tmp.replace(stamp)
        return True
    except OSError:  # read-only install: nothing to keep in step here
        return False
