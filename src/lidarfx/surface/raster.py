"""A georeferenced single-band raster and its writers.

:class:`Raster` holds a north-up float32 grid: ``array[0, 0]`` is the
north-west cell, ``origin`` the (x, y) of the north-west *corner*, square
cells of ``resolution`` map units.  NaN marks "no data".

Output formats (chosen by the file extension):

* ``.tif`` / ``.tiff`` — GeoTIFF.  Written with rasterio when it is installed
  (CRS from WKT or EPSG, deflate compression), otherwise by a small built-in
  writer (numpy only: uncompressed float32, GeoTIFF tags ModelPixelScale,
  ModelTiepoint and GeoKeyDirectory with the EPSG code when one is known,
  GDAL_NODATA = nan) plus a ``.tfw`` world file.
* ``.asc`` — ESRI ASCII grid (``NODATA_value -9999``) plus a ``.prj`` (ESRI WKT1, from the
  CRS's WKT or EPSG code) when the cloud has a CRS.

All files are written atomically (temporary file + rename).
"""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_path
from ..crs import prj_text as _prj_text
from ..errors import LidarfxError

__all__ = ["Raster", "RASTER_EXTENSIONS", "grid_layout"]

RASTER_EXTENSIONS = (".tif", ".tiff", ".asc")
ASC_NODATA = -9999.0


def grid_layout(lo: Any, hi: Any, resolution: float, *, max_cells: int,
                what: str = "raster") -> tuple[float, float, int, int]:
    """The cells of a raster product over ``lo`` = (xmin, ymin) .. ``hi`` = (xmax, ymax):
    ``(x0, y0, rows, cols)``.

    ``(x0, y0)``, the south-west corner, is snapped to multiples of ``resolution`` (adjacent tiles
    line up); column ``j`` covers ``x0 + j·r <= x < x0 + (j + 1)·r`` and the rows likewise from
    the south, so a point on a cell edge belongs to the cell east / north of it, and the extent's
    east and north edges lie inside the last cells.  (The raster stores the rows north first.)
    A layout of more than ``max_cells`` cells is refused before anything is allocated."""
    r = float(resolution)
    lo_x, lo_y, hi_x, hi_y = float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
    est = (max((hi_x - lo_x) / r, 1.0), max((hi_y - lo_y) / r, 1.0))  # at most (cols, rows), as floats
    if not all(math.isfinite(v) for v in est) or est[0] * est[1] > max_cells:
        rows, cols = (f"{math.ceil(v):g}" if math.isfinite(v) else "inf" for v in (est[1], est[0]))
        raise LidarfxError(f"{what} of {rows} x {cols} cells of {r:g} is too large "
                           f"(at most {max_cells:,} cells); use a coarser resolution or tiles")
    if not (math.isfinite(lo_x / r) and math.isfinite(lo_y / r)):
        raise LidarfxError(f"{what} cells of {r:g} are too small for coordinates of "
                           f"{max(abs(lo_x), abs(lo_y)):g}; use a coarser resolution")
    x0 = math.floor(lo_x / r) * r
    y0 = math.floor(lo_y / r) * r
    cols = max(1, int(math.floor((hi_x - x0) / r)) + 1)
    rows = max(1, int(math.floor((hi_y - y0) / r)) + 1)
    if rows * cols > max_cells:
        raise LidarfxError(f"{what} of {rows:g} x {cols:g} cells of {r:g} is too large "
                           f"(at most {max_cells:,} cells); use a coarser resolution or tiles")
    return x0, y0, rows, cols


@dataclass
class Raster:
    """North-up single-band raster.

    Attributes
    ----------
    array:
        ``(rows, cols)`` float32 values, row 0 = north; NaN = no data.
    origin:
        ``(x, y)`` of the north-west corner of cell ``[0, 0]`` (map units).
    resolution:
        Cell edge (map units).
    crs:
        ``{"wkt": ..., "epsg": ...}`` (either may be ``None``) or ``None``.
    """

    array: np.ndarray
    origin: tuple[float, float]
    resolution: float
    crs: dict[str, Any] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.array.shape)  # type: ignore[return-value]

    @property
    def transform(self) -> tuple[float, float, float, float, float, float]:
        """GDAL geotransform ``(x0, res, 0, y0, 0, -res)`` (x0, y0 = north-west corner)."""
        x0, y0 = self.origin
        r = self.resolution
        return (float(x0), float(r), 0.0, float(y0), 0.0, -float(r))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the raster's outer edges."""
        x0, y0 = self.origin
        rows, cols = self.array.shape
        return (x0, y0 - rows * self.resolution, x0 + cols * self.resolution, y0)

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """x of the column centres (cols,) and y of the row centres (rows,)."""
        x0, y0 = self.origin
        rows, cols = self.array.shape
        r = self.resolution
        return x0 + (np.arange(cols) + 0.5) * r, y0 - (np.arange(rows) + 0.5) * r

    def cell_of(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(row, col)`` of the cell that holds each map coordinate; points outside the
        raster take the nearest edge cell."""
        rows, cols = self.array.shape
        col = np.floor((np.asarray(x, dtype=np.float64) - self.origin[0]) / self.resolution)
        row = np.floor((self.origin[1] - np.asarray(y, dtype=np.float64)) / self.resolution)
        return (np.clip(row, 0, rows - 1).astype(np.int64), np.clip(col, 0, cols - 1).astype(np.int64))

    def sample(self, x: Any, y: Any) -> np.ndarray:
        """Bilinear value at map coordinates (cell values sit at cell centres).

        Points outside the outer cell centres take the edge values; NaN cells
        propagate NaN, and so do NaN or infinite coordinates.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        bad = ~(np.isfinite(x) & np.isfinite(y))
        if bad.any():
            x, y = np.where(bad, self.origin[0], x), np.where(bad, self.origin[1], y)
        rows, cols = self.array.shape
        a = self.array.astype(np.float64)
        fx = np.clip((x - self.origin[0]) / self.resolution - 0.5, 0.0, cols - 1.0)
        fy = np.clip((self.origin[1] - y) / self.resolution - 0.5, 0.0, rows - 1.0)
        j0 = np.minimum(np.floor(fx).astype(np.int64), max(cols - 2, 0))
        i0 = np.minimum(np.floor(fy).astype(np.int64), max(rows - 2, 0))
        j1 = np.minimum(j0 + 1, cols - 1)
        i1 = np.minimum(i0 + 1, rows - 1)
        tx, ty = fx - j0, fy - i0
        top = a[i0, j0] * (1 - tx) + a[i0, j1] * tx
        bot = a[i1, j0] * (1 - tx) + a[i1, j1] * tx
        out = top * (1 - ty) + bot * ty
        return np.where(bad, np.nan, out) if bad.any() else out

    # ---------------------------------------------------------------- writing
    def write(self, path: str | os.PathLike, *, engine: str = "auto") -> Path:
        """Write the raster; the extension chooses the format (see module doc).

        ``engine`` (GeoTIFF only): ``"auto"`` (rasterio if installed, else the
        built-in writer), ``"rasterio"`` or ``"builtin"``.  Returns the path.
        """
        p = Path(path)
        ext = p.suffix.lower()
        if ext not in RASTER_EXTENSIONS:
            raise LidarfxError(
                f"{p}: unknown raster extension {p.suffix or '(none)'!r}; use one of {', '.join(RASTER_EXTENSIONS)}"
            )
        if engine not in ("auto", "rasterio", "builtin"):
            raise LidarfxError(f"unknown raster engine {engine!r}; use auto, rasterio or builtin")
        if ext == ".asc":
            self._write_asc(p)
            return p
        use_rio = engine == "rasterio"
        if engine == "auto":
            try:
                import rasterio  # noqa: F401

                use_rio = True
            except ImportError:
                use_rio = False
        if use_rio:
            self._write_rasterio(p)
        else:
            self._write_geotiff_builtin(p)
        return p

    def _write_rasterio(self, p: Path) -> None:
        try:
            import rasterio
            from rasterio.crs import CRS
            from rasterio.transform import Affine
        except ImportError:
            raise LidarfxError("engine 'rasterio' needs the rasterio package (pip install rasterio)") from None
        crs = None
        if self.crs:
            try:
                if self.crs.get("wkt"):
                    crs = CRS.from_wkt(self.crs["wkt"])
                elif self.crs.get("epsg"):
                    crs = CRS.from_epsg(int(self.crs["epsg"]))
            except Exception:  # an unparsable CRS must not lose the DTM
                crs = CRS.from_epsg(int(self.crs["epsg"])) if self.crs.get("epsg") else None
        rows, cols = self.array.shape
        x0, y0 = self.origin
        with atomic_path(p) as tmp:
            with rasterio.open(
                tmp,
                "w",
                driver="GTiff",
                height=rows,
                width=cols,
                count=1,
                dtype="float32",
                crs=crs,
                transform=Affine(self.resolution, 0.0, x0, 0.0, -self.resolution, y0),
                nodata=np.nan,
                compress="deflate",
            ) as dst:
                dst.write(self.array.astype(np.float32), 1)

    def _write_geotiff_builtin(self, p: Path) -> None:
        data = _geotiff_bytes(self)
        with atomic_path(p) as tmp:
            tmp.write_bytes(data)
        world = p.with_suffix(".tfw")
        with atomic_path(world) as tmp:
            tmp.write_text(_world_file(self))

    def _write_asc(self, p: Path) -> None:
        rows, cols = self.array.shape
        x0, y0 = self.origin
        arr = np.where(np.isfinite(self.array), self.array, ASC_NODATA)
        header = (
            f"ncols {cols}\nnrows {rows}\nxllcorner {x0!r}\nyllcorner {y0 - rows * self.resolution!r}\n"
            f"cellsize {self.resolution!r}\nNODATA_value {ASC_NODATA:g}\n"
        )
        with atomic_path(p) as tmp:
            with open(tmp, "w") as fh:
                fh.write(header)
                np.savetxt(fh, arr, fmt="%.3f")
        wkt = _prj_text(self.crs)
        if wkt:
            with atomic_path(p.with_suffix(".prj")) as tmp:
                tmp.write_text(wkt)


def _world_file(r: Raster) -> str:
    x0, y0 = r.origin
    res = r.resolution
    # world files give the centre of the upper-left cell
    return f"{res!r}\n0.0\n0.0\n{-res!r}\n{x0 + res / 2!r}\n{y0 - res / 2!r}\n"


# GeoTIFF (TIFF 6.0 + GeoTIFF 1.0 keys), little endian, one strip.
_SHORT, _LONG, _DOUBLE, _ASCII = 3, 4, 12, 2
_TYPE_FMT = {_SHORT: "H", _LONG: "I", _DOUBLE: "d", _ASCII: "s"}
_TYPE_SIZE = {_SHORT: 2, _LONG: 4, _DOUBLE: 8, _ASCII: 1}


def _geokeys(crs: dict[str, Any] | None) -> list[int]:
    keys: list[tuple[int, int]] = [(1025, 1)]  # GTRasterTypeGeoKey = RasterPixelIsArea
    epsg = (crs or {}).get("epsg")
    if epsg:
        if (crs or {}).get("geographic"):
            keys += [(1024, 2), (2048, int(epsg))]  # geographic model, GeographicTypeGeoKey
        else:
            keys += [(1024, 1), (3072, int(epsg))]  # projected model, ProjectedCSTypeGeoKey
    keys.sort()
    out = [1, 1, 0, len(keys)]
    for k, v in keys:
        out += [k, 0, 1, v]
    return out


def _geotiff_bytes(r: Raster) -> bytes:
    rows, cols = r.array.shape
    pixels = np.ascontiguousarray(r.array, dtype="<f4").tobytes()
    x0, y0 = r.origin
    entries: list[tuple[int, int, Any]] = [
        (256, _LONG, [cols]),
        (257, _LONG, [rows]),
        (258, _SHORT, [32]),
        (259, _SHORT, [1]),  # no compression
        (262, _SHORT, [1]),  # BlackIsZero
        (273, _LONG, [0]),  # strip offset, patched below
        (277, _SHORT, [1]),
        (278, _LONG, [rows]),
        (279, _LONG, [len(pixels)]),
        (284, _SHORT, [1]),
        (339, _SHORT, [3]),  # IEEE float
        (33550, _DOUBLE, [r.resolution, r.resolution, 0.0]),
        (33922, _DOUBLE, [0.0, 0.0, 0.0, float(x0), float(y0), 0.0]),
        (34735, _SHORT, _geokeys(r.crs)),
        (42113, _ASCII, b"nan\x00"),
    ]
    n = len(entries)
    ifd_offset = 8
    ifd_size = 2 + 12 * n + 4
    extra_offset = ifd_offset + ifd_size
    extra = bytearray()
    packed = []
    for tag, typ, vals in entries:
        if typ == _ASCII:
            payload = bytes(vals)
            count = len(payload)
        else:
            payload = struct.pack("<" + _TYPE_FMT[typ] * len(vals), *vals)
            count = len(vals)
        if len(payload) <= 4:
            packed.append([tag, typ, count, payload.ljust(4, b"\x00"), None])
        else:
            if (extra_offset + len(extra)) % 2:
                extra += b"\x00"
            packed.append([tag, typ, count, None, extra_offset + len(extra)])
            extra += payload
    data_offset = extra_offset + len(extra)
    data_offset += data_offset % 2
    out = bytearray(b"II*\x00" + struct.pack("<I", ifd_offset))
    out += struct.pack("<H", n)
    for tag, typ, count, inline, off in packed:
        if tag == 273:
            inline = struct.pack("<I", data_offset)
        value = inline if inline is not None else struct.pack("<I", off)
        out += struct.pack("<HHI", tag, typ, count) + value
    out += struct.pack("<I", 0)  # no next IFD
    out += extra
    out += b"\x00" * (data_offset - len(out))
    out += pixels
    return bytes(out)
