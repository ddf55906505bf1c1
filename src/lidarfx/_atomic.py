"""Atomic output: write to a temporary file in the target folder, rename at the end.

Whether an existing output may be replaced is one switch, :data:`OVERWRITE` (a context
variable): the Python API replaces what it is told to write, like ``numpy.save``; the command
line (:func:`lidarfx.cli.main`) turns it off unless ``--force`` is given, so that every early
output check (:func:`check_output_folder`, :func:`check_new_folder`) refuses an existing output
before any work and :func:`atomic_path` refuses it again at the final rename.

A temporary file is named ``.STEM.lidarfx-HOST-PID-XXXXXXXX.partSUFFIX`` beside its target.  A
run that is killed (SIGKILL, power loss) cannot remove it; the next :func:`atomic_path` for the
same target removes the ones whose process, on this host, is gone.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import re
import socket
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import ENVIRONMENT_ERRNOS, LidarfxError

OVERWRITE: contextvars.ContextVar[bool] = contextvars.ContextVar("lidarfx_overwrite", default=True)
"""True (the default): outputs replace existing files.  False: an existing output is an error
("OUT exists; give --force to overwrite it"); ``lidarfx`` sets it for a run without ``--force``."""

_HOST = re.sub(r"[^A-Za-z0-9]", "_", socket.gethostname() or "host")[:40]
_TEMP_MARK = ".lidarfx-"


@contextlib.contextmanager
def overwriting(allowed: bool = True) -> Iterator[None]:
    """Within the block, outputs replace existing files (``allowed``) or refuse them."""
    token = OVERWRITE.set(bool(allowed))
    try:
        yield
    finally:
        OVERWRITE.reset(token)


def exists_message(path: str | os.PathLike) -> str:
    return f"{path} exists; give --force to overwrite it"


def check_new_file(path: str | os.PathLike) -> None:
    """Unless :data:`OVERWRITE` allows it, an error when the output file ``path`` exists."""
    if not OVERWRITE.get() and os.path.lexists(path) and not os.path.isdir(path):
        raise LidarfxError(exists_message(path))


def is_temporary(name: str) -> bool:
    """True for the name of a temporary file of :func:`atomic_path`."""
    return name.startswith(".") and _TEMP_MARK in name and ".part" in name


def check_new_folder(path: str | os.PathLike) -> None:
    """Unless :data:`OVERWRITE` allows it, an error when the output folder ``path`` exists and
    holds anything but temporary files of killed runs: a run writes into an empty or new folder,
    so a folder never mixes the products of two runs without ``--force``."""
    p = Path(path)
    if OVERWRITE.get() or not p.is_dir():
        return
    if any(not is_temporary(e.name) for e in p.iterdir()):
        raise LidarfxError(f"{p} is not empty; give --force to write into it (files of the same name are replaced)")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``.

    On any exception the temporary file is removed and ``path`` is left as it was,
    so a failed run never leaves a half-written output behind.  Without :data:`OVERWRITE`
    an existing ``path`` is refused at the start and again at the rename (the temporary file
    is removed).  A disk-full, file-too-large, quota, read-only or I/O error while writing
    leaves as ``OSError(errno, strerror, path)``: it names the output, not the temporary file.
    """
    target = Path(path)
    folder = check_output_folder(target)
    sfx = suffix if suffix is not None else "".join(target.suffixes[-1:])
    prefix = f".{target.stem}{_TEMP_MARK}"
    _remove_stale(folder, prefix, f".part{sfx}")
    fd, tmp = tempfile.mkstemp(prefix=f"{prefix}{_HOST}-{os.getpid()}-", suffix=f".part{sfx}", dir=folder)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; outputs follow the umask
        yield tmp_path
        _install(tmp_path, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        env = _os_failure(exc)
        if env is not None and (not env.filename or str(env.filename) == str(tmp_path)):
            raise OSError(env.errno, env.strerror or os.strerror(env.errno), str(target)) from exc
        raise


def _install(tmp: Path, target: Path) -> None:
    """Rename ``tmp`` to ``target``; without :data:`OVERWRITE` never over an existing file (a
    hard link fails when ``target`` exists; where links are not supported, checked just before)."""
    if OVERWRITE.get():
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise LidarfxError(exists_message(target)) from None
    except OSError:  # no hard links here (some network and FAT file systems)
        if os.path.lexists(target):
            raise LidarfxError(exists_message(target)) from None
        os.replace(tmp, target)
        return
    with contextlib.suppress(OSError):
        tmp.unlink()


def _os_failure(exc: BaseException) -> OSError | None:
    """The disk-full (and alike) OSError ``exc`` is or was raised from, else None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS:
            return exc
        exc = exc.__cause__ if exc.__cause__ is not None else (None if exc.__suppress_context__ else exc.__context__)
    return None


def _remove_stale(folder: Path, prefix: str, suffix: str) -> None:
    """Remove the temporary files of ``prefix``/``suffix`` in ``folder`` whose process (this
    host's) no longer runs: what a killed run left behind."""
    try:
        names = [e.name for e in os.scandir(folder) if e.name.startswith(prefix) and e.name.endswith(suffix)]
    except OSError:
        return
    for name in names:
        host, _, rest = name[len(prefix):-len(suffix)].rpartition("-")
        host, _, pid = host.rpartition("-")
        if host != _HOST or not pid.isdigit() or int(pid) == os.getpid() or _alive(int(pid)):
            continue
        with contextlib.suppress(OSError):
            os.unlink(folder / name)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process
        return True
    return True


def check_output_folder(path: str | os.PathLike) -> Path:
    """The folder an output file goes to; an error when it does not exist or ``path`` is a folder,
    and (unless :data:`OVERWRITE` allows it) when ``path`` exists."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise LidarfxError(f"output folder does not exist: {folder}")
    if target.is_dir():
        raise LidarfxError(f"{target} is a folder; give an output file name")
    check_new_file(target)
    return folder


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_not_same_file(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    """Refuse to overwrite the input: input files are never modified."""
    s, d = Path(src), Path(dst)
    if d.exists() and s.exists() and os.path.samefile(s, d):
        raise LidarfxError(f"output {d} is the input file; choose another output path")
