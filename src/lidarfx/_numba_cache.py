"""Keep numba's on-disk kernel cache in step with the package's sources.

numba caches a compiled ``@njit(cache=True)`` function beside its source file (or under
``NUMBA_CACHE_DIR``) and checks only that file: a kernel that calls (and inlines) a function of
*another* module keeps its old machine code when only the callee changes (a documented
limitation, numba issue #1833).  lidarfx's kernels call across modules (the feature
engine calls ``plane.write_plane``, ``eigen.eigh3`` …), so an edited checkout or an
editable install could silently compute with stale code.

:func:`check` fingerprints every ``.py`` file of the package (path, size, mtime) and, when
the fingerprint differs from the one recorded at the last check, deletes the package's
numba cache files (``__pycache__/*.nbi``, ``*.nbc``, and the package's folders of
``NUMBA_CACHE_DIR``, which keeps its own record) before any kernel loads.  A fresh install
has no cache yet, so this costs nothing there; an unwritable install is left as it is (its
files do not change without a reinstall, which numba notices).
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


def _user_cache_folders(root: Path, cache_dir: Path) -> list[Path]:
    """The folders of ``cache_dir`` (``NUMBA_CACHE_DIR``) holding kernels of the package at ``root``
    (numba names them after the source folder: its name and the SHA-1 of its path)."""
    out = []
    for d in {p.parent for p in root.rglob("*.py")}:
        path = os.path.abspath(d)
        out.append(cache_dir / f"{os.path.basename(path)}_{hashlib.sha1(path.encode()).hexdigest()}")
    return out


def check(root: Path = ROOT, stamp: Path | None = None) -> bool:
    """Delete stale numba cache files of the package at ``root`` (its ``__pycache__`` folders, and
    its folders of ``NUMBA_CACHE_DIR`` when that is set); True when the sources changed."""
    changed = _check_one(root, STAMP if stamp is None else stamp,
                         lambda: list(root.rglob("__pycache__/*.nb[ic]")))
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if cache_dir and stamp is None:
        cd = Path(cache_dir)
        key = hashlib.sha1(str(root).encode()).hexdigest()[:16]
        changed |= _check_one(root, cd / f"lidarfx-{key}-sources.key",
                              lambda: [f for d in _user_cache_folders(root, cd) for f in d.glob("*.nb[ic]")])
    return changed


def _check_one(root: Path, stamp: Path, files) -> bool:
    try:
        key = fingerprint(root)
        if stamp.exists() and stamp.read_text() == key:
            return False
        for f in files():
            try:
                f.unlink()
            except FileNotFoundError:  # another process cleared it first
                pass
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(key)
        tmp.replace(stamp)
        return True
    except OSError:  # read-only install: nothing to keep in step here
        return False


NOTICE = ("lidarfx: compiling the numeric kernels for this machine (first run after an install or "
          "update; cached for the next runs)")


def _compile_notice_listener():
    """A numba event listener printing :data:`NOTICE` once, at the first kernel of lidarfx that
    numba compiles (loading one from the disk cache fires no compile event)."""
    from numba.core import event

    class CompileNotice(event.Listener):
        def __init__(self) -> None:
            self.stream = None
            self.shown = False

        def on_start(self, ev) -> None:
            if self.shown:
                return
            disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            module = getattr(getattr(disp, "py_func", None), "__module__", "") or ""
            if module.startswith("lidarfx"):
                import sys

                self.shown = True
                print(NOTICE, file=self.stream or sys.stderr, flush=True)

        def on_end(self, ev) -> None:
            pass

    listener = CompileNotice()
    event.register("numba:compile", listener)
    return listener


_notice = None


def announce_compiles(stream=None) -> None:
    """Print :data:`NOTICE` to ``stream`` (stderr) the first time a lidarfx kernel is compiled in
    this process (the CLI calls it; ``LIDARFX_COMPILE_NOTICE=0`` turns it off)."""
    global _notice
    if os.environ.get("LIDARFX_COMPILE_NOTICE", "1") == "0":
        return
    if _notice is None:
        _notice = _compile_notice_listener()
    _notice.stream = stream
