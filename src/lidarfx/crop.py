"""Cropping: keep the points inside a box or a polygon area (or outside, ``invert``).

Box (``bounds``)
    ``(xmin, ymin, xmax, ymax)`` or ``(xmin, ymin, xmax, ymax, zmin, zmax)`` in the cloud's
    coordinates; closed: a point on a face is inside (as PDAL ``filters.crop``).

Polygons (``polygon``)
    A shapely Polygon / MultiPolygon in the cloud's coordinates, or a file read by
    :func:`read_area`: GeoJSON (a geometry, a Feature or a FeatureCollection of Polygon /
    MultiPolygon geometries) or an ESRI shapefile of polygons (POLYGON, POLYGONZ, POLYGONM).  All
    polygons of a file together make the area (their union).  Any other geometry type is refused,
    naming it.  Shapefile rings are organised by containment, not by their winding (many files
    wind them the wrong way): a ring inside an odd number of others is a hole.  The test is exact
    and in plan (x, y; z of the polygon is ignored): a point is inside when it lies in the area or
    on its boundary (GEOS ``intersects`` on the prepared area), so holes are left out and
    multi-part areas kept whole.  Invalid polygons (self-intersections) are refused with GEOS's
    reason.

CRS
    A GeoJSON's legacy ``crs`` member (``urn:ogc:def:crs:EPSG::2154``) or a shapefile's ``.prj``
    gives the area's CRS.  When the area and the cloud both have one they must be the same in plan
    (:func:`lidarfx.reproject.same_horizontal`), else a one-line error; when either has none the
    coordinates are taken as they are (RFC 7946's WGS 84 default is not assumed: files written
    with projected coordinates and no ``crs`` member are common).

Buffer
    ``buffer`` metres (converted for clouds in feet; refused for geographic clouds, whose degrees
    are no length) around the area or box: a point is inside when its plan distance to the area is
    at most ``buffer`` (GEOS ``dwithin``: exact distances, no polygonal approximation of the round
    corners).  A negative buffer shrinks the area: inside and at least ``-buffer`` from its
    boundary.  For a box the buffer widens x and y, not z.

An empty result is not an error here (the function returns an empty cloud); ``lidarfx crop``
refuses it unless ``--allow-empty``.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError

__all__ = ["Area", "read_area", "parse_bounds", "crop_mask", "area_mask", "crop", "BLOCK_POINTS"]

BLOCK_POINTS = 1 << 20
"""Points tested at a time (shapely point geometries are made per block for buffered areas)."""

_POLYGON_SHAPES = {5: "POLYGON", 15: "POLYGONZ", 25: "POLYGONM"}


@dataclass
class Area:
    """A crop area: the union of the file's polygons, its CRS (``pyproj.CRS`` or None), where it
    came from and how many polygons it had."""

    geometry: Any
    crs: Any = None
    source: str = ""
    polygons: int = 0


# --------------------------------------------------------------------------- reading areas
def parse_bounds(text) -> tuple[float, ...]:
    """``xmin,ymin,xmax,ymax[,zmin,zmax]`` (a string or a sequence) as 4 or 6 finite floats with
    min <= max per axis, else a one-line error."""
    if isinstance(text, str):
        try:
            vals = [float(v) for v in text.replace(" ", "").split(",")]
        except ValueError:
            raise LidarfxError(f"--bounds must be xmin,ymin,xmax,ymax[,zmin,zmax] numbers, got {text!r}") from None
    else:
        try:
            vals = [float(v) for v in text]
        except (TypeError, ValueError):
            raise LidarfxError(f"bounds must be xmin, ymin, xmax, ymax[, zmin, zmax] numbers, got {text!r}") from None
    if len(vals) not in (4, 6) or not all(math.isfinite(v) for v in vals):
        raise LidarfxError(f"--bounds must be 4 or 6 finite numbers xmin,ymin,xmax,ymax[,zmin,zmax], got {text!r}")
    if vals[0] > vals[2] or vals[1] > vals[3] or (len(vals) == 6 and vals[4] > vals[5]):
        raise LidarfxError(f"--bounds: a minimum exceeds its maximum in {text!r} (order: xmin,ymin,xmax,ymax[,zmin,zmax])")
    return tuple(vals)


def _check_polygonal(geom, where: str):
    import shapely

    if geom.is_empty:
        raise LidarfxError(f"{where}: the area is empty")
    if geom.geom_type not in ("Polygon", "MultiPolygon"):
        raise LidarfxError(f"{where}: holds {geom.geom_type} geometry; crop needs Polygon or MultiPolygon areas")
    if not geom.is_valid:
        raise LidarfxError(f"{where}: invalid polygon ({shapely.is_valid_reason(geom)}); repair it first "
                           "(e.g. QGIS Fix geometries, or shapely.make_valid)")
    return geom


def _geojson_crs(doc: dict, where: str):
    from .reproject import parse_crs

    crs = doc.get("crs") if isinstance(doc, dict) else None
    if not crs:
        return None
    name = (crs.get("properties") or {}).get("name") if isinstance(crs, dict) else None
    if not isinstance(name, str):
        raise LidarfxError(f"{where}: a 'crs' member without a name")
    text = name
    if "EPSG" in name.upper():
        code = name.replace("::", ":").rstrip(":").split(":")[-1]
        text = f"EPSG:{code}" if code.isdigit() else name
    if "CRS84" in name.upper():
        text = "OGC:CRS84"
    return parse_crs(text, f"{where}: crs")


def _read_geojson(path: Path) -> Area:
    from shapely.geometry import shape
    import shapely

    where = str(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:  # deep nesting: RecursionError
        raise LidarfxError(f"{where}: not a GeoJSON file ({' '.join(str(exc).split())[:120]})") from None
    if not isinstance(doc, dict) or "type" not in doc:
        raise LidarfxError(f"{where}: not a GeoJSON object (no 'type')")
    kind = doc["type"]
    if kind == "FeatureCollection":
        geoms = [f.get("geometry") for f in doc.get("features") or [] if isinstance(f, dict)]
    elif kind == "Feature":
        geoms = [doc.get("geometry")]
    else:
        geoms = [doc]
    geoms = [g for g in geoms if g]
    if not geoms:
        raise LidarfxError(f"{where}: no geometry")
    other = sorted({str(g.get("type")) for g in geoms if g.get("type") not in ("Polygon", "MultiPolygon")})
    if other:
        raise LidarfxError(f"{where}: holds {', '.join(other)} geometry; crop needs Polygon or MultiPolygon areas")
    try:
        parts = [shape(g) for g in geoms]
    except Exception as exc:  # noqa: BLE001 - shapely's message on malformed coordinates
        raise LidarfxError(f"{where}: malformed polygon coordinates ({' '.join(str(exc).split())[:120]})") from None
    for p in parts:
        _check_polygonal(p, where)
    geom = parts[0] if len(parts) == 1 else shapely.union_all(parts)
    return Area(_check_polygonal(geom, where), _geojson_crs(doc, where), where, len(parts))


def _organise_rings(rings: list[np.ndarray]):
    """Polygons of one shapefile record from its rings, by containment: a ring inside an odd number
    of other rings is a hole of the smallest ring around it (winding is not trusted)."""
    from shapely.geometry import MultiPolygon, Polygon

    shells = [Polygon(r) for r in rings]
    areas = [s.area for s in shells]
    depth, parent = [0] * len(rings), [-1] * len(rings)
    for i, si in enumerate(shells):
        pt = si.representative_point()
        best = -1
        for j, sj in enumerate(shells):
            if j != i and areas[j] > areas[i] and sj.contains(pt):
                depth[i] += 1
                if best < 0 or areas[j] < areas[best]:
                    best = j
        parent[i] = best
    polys = []
    for i, r in enumerate(rings):
        if depth[i] % 2 == 0:
            holes = [rings[k] for k in range(len(rings)) if parent[k] == i and depth[k] % 2 == 1]
            polys.append(Polygon(r, holes))
    return polys[0] if len(polys) == 1 else MultiPolygon(polys)


def _read_shapefile(path: Path) -> Area:
    import shapely

    where = str(path)
    try:
        import shapefile
    except ImportError:  # pragma: no cover - pyshp is a dependency
        raise LidarfxError("reading shapefiles needs pyshp (pip install pyshp)") from None
    try:
        reader = shapefile.Reader(str(path))
    except Exception as exc:  # noqa: BLE001 - pyshp's errors on damaged files
        raise LidarfxError(f"{where}: not a readable shapefile ({' '.join(str(exc).split())[:120]})") from None
    with reader:
        kind = reader.shapeType
        if kind not in _POLYGON_SHAPES:
            raise LidarfxError(f"{where}: holds {reader.shapeTypeName} shapes; crop needs a polygon shapefile "
                               "(POLYGON, POLYGONZ or POLYGONM)")
        parts = []
        for shp in reader.iterShapes():
            if not shp.points:
                continue
            pts = np.asarray(shp.points, dtype=np.float64)[:, :2]
            cuts = list(shp.parts) + [len(pts)]
            rings = [pts[a:b] for a, b in zip(cuts[:-1], cuts[1:]) if b - a >= 3]
            if rings:
                parts.append(_check_polygonal(_organise_rings(rings), where))
    if not parts:
        raise LidarfxError(f"{where}: no polygon")
    geom = parts[0] if len(parts) == 1 else shapely.union_all(parts)
    crs = None
    prj = path.with_suffix(".prj")
    if not prj.exists():
        prj = next((q for q in path.parent.glob(path.stem + ".*") if q.suffix.lower() == ".prj"), prj)
    if prj.exists():
        from pyproj import CRS
        from pyproj.exceptions import CRSError

        try:
            crs = CRS.from_wkt(prj.read_text(errors="replace").strip())
        except CRSError as exc:
            raise LidarfxError(f"{prj}: PROJ cannot read this CRS ({' '.join(str(exc).split())[:120]})") from None
    return Area(_check_polygonal(geom, where), crs, where, len(parts))


def read_area(path: str | os.PathLike) -> Area:
    """The crop area of a GeoJSON (``.geojson`` / ``.json``) or shapefile (``.shp``) file: the
    union of its polygons and its CRS (see the module docstring); one-line errors for files that
    are not polygons."""
    p = Path(path)
    if not p.is_file():
        raise LidarfxError(f"polygon file not found: {p}")
    ext = p.suffix.lower()
    if ext in (".geojson", ".json"):
        return _read_geojson(p)
    if ext == ".shp":
        return _read_shapefile(p)
    raise LidarfxError(f"{p}: polygons are read from GeoJSON (.geojson, .json) or shapefiles (.shp)")


# --------------------------------------------------------------------------- the test
def _as_area(polygon, cloud) -> Area:
    if isinstance(polygon, Area):
        area = polygon
    elif isinstance(polygon, (str, os.PathLike)):
        area = read_area(polygon)
    else:
        area = Area(_check_polygonal(polygon, "polygon"), None, "polygon", 1)
    if area.crs is not None:
        from .reproject import crs_label, crs_of, same_horizontal

        cloud_crs = crs_of(cloud, cloud.meta.get("source"))
        if cloud_crs is not None and not same_horizontal(cloud_crs, area.crs):
            raise LidarfxError(f"{area.source} is in {crs_label(area.crs)} but the cloud in {crs_label(cloud_crs)}; "
                               "give the area in the cloud's CRS (e.g. ogr2ogr -t_srs) or reproject the cloud")
    return area


def _buffer_units(cloud, buffer: float, units: str) -> float:
    from .crs import check_units, cloud_crs, length_to_units

    check_units(units)
    b = float(buffer)
    if not math.isfinite(b):
        raise LidarfxError(f"buffer must be a finite number of metres, got {buffer!r}")
    if b and units == "auto" and (cloud_crs(cloud) or {}).get("geographic"):
        raise LidarfxError("a buffer in metres needs projected coordinates; this cloud is in degrees "
                           "(reproject it first, or give units='native' for a buffer in degrees)")
    return float(length_to_units(cloud, b, units))


def crop_mask(cloud: PointCloud, *, bounds: Sequence[float] | str | None = None, polygon=None,
              buffer: float = 0.0, invert: bool = False, units: str = "auto") -> np.ndarray:
    """The boolean mask of the points kept by :func:`crop` (see the module docstring)."""
    if (bounds is None) == (polygon is None):
        raise LidarfxError("give exactly one of bounds (--bounds) and polygon (--polygon)")
    d = _buffer_units(cloud, buffer, units)
    xyz = cloud.xyz
    if bounds is not None:
        b = parse_bounds(bounds)
        x, y = xyz[:, 0], xyz[:, 1]
        keep = (x >= b[0] - d) & (x <= b[2] + d) & (y >= b[1] - d) & (y <= b[3] + d)
        if len(b) == 6:
            keep &= (xyz[:, 2] >= b[4]) & (xyz[:, 2] <= b[5])
        return ~keep if invert else keep
    area = _as_area(polygon, cloud)
    keep = area_mask(area.geometry, xyz[:, 0], xyz[:, 1], d)
    return ~keep if invert else keep


def area_mask(geometry, x: np.ndarray, y: np.ndarray, buffer: float = 0.0) -> np.ndarray:
    """Whether each point (x, y) lies in the polygon area or on its boundary, or within ``buffer``
    of it (``buffer < 0``: inside and at least ``-buffer`` from the boundary); coordinate units."""
    import shapely

    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    keep = np.zeros(len(x), dtype=bool)
    if not len(x):
        return keep
    geom = geometry
    test_geom = geometry.boundary if buffer < 0 else geometry
    shapely.prepare(geom)
    shapely.prepare(test_geom)
    reach = max(buffer, 0.0)
    x0, y0, x1, y1 = geometry.bounds
    cand = np.flatnonzero((x >= x0 - reach) & (x <= x1 + reach) & (y >= y0 - reach) & (y <= y1 + reach))
    for a in range(0, len(cand), BLOCK_POINTS):
        idx = cand[a:a + BLOCK_POINTS]
        inside = shapely.intersects_xy(geom, x[idx], y[idx])
        if buffer > 0:
            out = ~inside
            if out.any():
                pts = shapely.points(x[idx[out]], y[idx[out]])
                inside[out] = shapely.dwithin(geom, pts, buffer)
        elif buffer < 0 and inside.any():
            pts = shapely.points(x[idx[inside]], y[idx[inside]])
            inside[inside] = shapely.distance(test_geom, pts) >= -buffer
        keep[idx] = inside
    return keep


def crop(cloud: PointCloud, *, bounds: Sequence[float] | str | None = None, polygon=None, buffer: float = 0.0,
         invert: bool = False, units: str = "auto") -> PointCloud:
    """The points of ``cloud`` inside a box (``bounds``) or a polygon area (``polygon``: a shapely
    Polygon / MultiPolygon in the cloud's coordinates, an :class:`Area`, or a GeoJSON / shapefile
    path), widened by ``buffer`` metres; with ``invert`` the points outside.  Every attribute and
    the header pass through; ``meta["crop"]`` counts what was kept.  May be empty."""
    mask = crop_mask(cloud, bounds=bounds, polygon=polygon, buffer=buffer, invert=invert, units=units)
    out = cloud.subset(mask)
    out.meta["crop"] = {"kept": int(mask.sum()), "points": len(cloud)}
    return out
