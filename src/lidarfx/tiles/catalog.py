"""The inputs of a tiled run: one file, several files or a folder of LAS / LAZ / COPC tiles."""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import LidarfxError

SUFFIXES = (".las", ".laz")


def inputs_of(text: str) -> list[str] | str:
    """A file or folder as given; a pattern with * ? [ expanded (sorted), or a one-line error."""
    import glob

    if any(c in text for c in "*?[") and not Path(text).exists():
        found = sorted(glob.glob(text))
        if not found:
            raise LidarfxError(f"no file matches {text}")
        return found
    return text


@dataclass
class Source:
    """One input file: its path, points (from the header, checked against the file), the bounds
    of its header and where its points start in the catalog's global numbering."""

    path: str
    points: int
    mins: np.ndarray
    maxs: np.ndarray
    first: int = 0
    size: int = 0
    mtime_ns: int = 0


@dataclass
class Catalog:
    """The input files of a run, in the order their points are numbered (global index =
    ``source.first`` + index in the file)."""

    sources: list[Source] = field(default_factory=list)

    @property
    def points(self) -> int:
        return sum(s.points for s in self.sources)

    @property
    def mins(self) -> np.ndarray:
        return np.min([s.mins for s in self.sources], axis=0)

    @property
    def maxs(self) -> np.ndarray:
        return np.max([s.maxs for s in self.sources], axis=0)

    @property
    def density(self) -> float:
        """Mean points per square coordinate unit over the bounding box in plan."""
        area = max(float((self.maxs[0] - self.mins[0]) * (self.maxs[1] - self.mins[1])), 1e-6)
        return self.points / area

    @property
    def bytes(self) -> int:
        return sum(s.size for s in self.sources)

    def key(self) -> str:
        """Fingerprint of the inputs (path, size, mtime): a resumed run needs the same."""
        h = hashlib.sha256()
        for s in self.sources:
            h.update(f"{os.path.abspath(s.path)}\0{s.size}\0{s.mtime_ns}\n".encode())
        return h.hexdigest()[:16]


def expand_inputs(inputs: str | os.PathLike | Sequence[str | os.PathLike], *, any_format: bool = False,
                  none: str = "no input given") -> list[Path]:
    """Files of ``inputs``: a file, a folder (its ``*.las`` / ``*.laz``, sorted by name; COPC
    files are LAZ) or a list of those.  One-line errors for a missing path, an empty folder,
    a file that is not LAS/LAZ (``any_format``: files of any format pass, for the caller to
    check) or a file given twice; ``none``: the message for no input."""
    items = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    if not items:
        raise LidarfxError(none)
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in SUFFIXES)
            if not found:
                raise LidarfxError(f"{p}: no .las / .laz files in this folder")
            out += found
        elif any_format:
            out.append(p)
        elif p.is_file():
            if p.suffix.lower() not in SUFFIXES:
                raise LidarfxError(f"{p}: tiled runs read LAS / LAZ files (convert it first: lidarfx convert)")
            out.append(p)
        else:
            raise LidarfxError(f"input not found: {p}")
    seen: set[str] = set()
    for p in out:
        k = os.path.realpath(p)
        if k in seen:
            raise LidarfxError(f"{p} is given twice")
        seen.add(k)
    return out


def open_catalog(inputs: str | os.PathLike | Sequence[str | os.PathLike]) -> Catalog:
    """Read the headers of every input (not the points).  A header whose point count the file
    cannot hold (uncompressed), or with bounds that are not finite, is a one-line error."""
    from ..io import one_line
    from ..io.las import READ_ERRORS, check_size, read_header

    cat = Catalog()
    first = 0
    for p in expand_inputs(inputs):
        try:
            h = read_header(p)
        except READ_ERRORS as exc:
            raise LidarfxError(f"cannot read {p}: {one_line(exc)}") from exc
        check_size(p, h)
        mins, maxs = np.asarray(h.mins, dtype=np.float64), np.asarray(h.maxs, dtype=np.float64)
        n = int(h.point_count)
        if n and not (np.isfinite(mins).all() and np.isfinite(maxs).all() and (maxs >= mins).all()):
            raise LidarfxError(f"{p}: the header's bounds are not valid ({mins} .. {maxs})")
        st = p.stat()
        cat.sources.append(Source(str(p), n, mins, maxs, first, st.st_size, st.st_mtime_ns))
        first += n
    if cat.points == 0:
        raise LidarfxError("the inputs hold no points")
    return cat
