"""Atomic output: write to a temporary file in the target folder, rename at the end."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import LidarfxError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``.

    On any exception the temporary file is removed and ``path`` is left as it was,
    so a failed run never leaves a half-written output behind.
    """
    target = Path(path)
    folder = check_output_folder(target)
    sfx = suffix if suffix is not None else "".join(target.suffixes[-1:])
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".part{sfx}", dir=folder)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes 0600; outputs follow the umask
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def check_output_folder(path: str | os.PathLike) -> Path:
    """The folder an output file goes to; an error when it does not exist or ``path`` is a folder."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise LidarfxError(f"output folder does not exist: {folder}")
    if target.is_dir():
        raise LidarfxError(f"{target} is a folder; give an output file name")
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
