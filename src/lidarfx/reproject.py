"""Reprojection of point clouds with PROJ (pyproj), and the CRS records of LAS headers.

What is transformed
    x, y and, when both CRSs have a vertical axis (a compound CRS such as ``EPSG:2154+5720``, or a
    3-D geographic CRS such as ``EPSG:4979``), z.  The operation is the one PROJ ranks best for the
    pair (``pyproj.transformer.TransformerGroup``, ``always_xy``: x = easting / longitude).  When
    that operation needs a grid (a geoid model, a datum-shift grid) PROJ does not have on this
    machine, the run is refused with a one-line error naming the grid, instead of falling back to a
    worse operation that ignores it.  PROJ's network access stays off (``pyproj.network``): grids
    are never downloaded.  When PROJ knows only a *ballpark* operation for the pair (one that
    leaves heights unchanged between two vertical datums, or ignores a datum shift), the run is
    refused too unless ``ballpark=True`` (``--ballpark``).

The source CRS
    The cloud's (LAS WKT, else GeoTIFF keys: projected or geographic EPSG code plus the vertical
    key when present), or ``source`` (``--from``), which wins with a warning when the file says
    something else.

The header
    The CRS records are rewritten: LAS 1.4 gets one OGC WKT VLR (WKT1 as GDAL writes it; WKT2 when
    WKT1 cannot express the CRS) and the WKT bit of the global encoding; LAS 1.0-1.3 gets GeoTIFF
    keys (EPSG codes of the horizontal and vertical parts, their linear units) when the CRS has
    EPSG codes, and the WKT VLR as well (read by PDAL, GDAL, LAStools and lidarfx).  Older CRS
    records (GeoTIFF keys, WKT, the liblas copy) are removed.  Every other VLR, the point format
    and the attributes pass through.

Scales and offsets (:func:`output_frame`)
    An axis the operation leaves unchanged keeps its scale and offset (so its raw integers too).
    Otherwise the scale keeps the source's resolution in metres, rounded down to a power of ten in
    the new unit: 0.01 m becomes 0.01 ft (0.0328 ft rounded down), 1e-8 degree (about 1.1 mm) or
    0.001 m from 0.01 US survey ft.  A degree counts as 111 319.5 m (the equator; finer
    elsewhere).  ``scale`` overrides.  Offsets are the minimum rounded down to a whole unit, or the
    middle when the extent needs both halves of the 32-bit range; a one-line error when the extent
    does not fit at that scale.
"""
from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, LidarfxWarning

__all__ = ["parse_crs", "crs_of", "same_crs", "same_horizontal", "crs_label", "set_crs", "transformer",
           "output_frame", "check_scale", "heights_note", "reproject", "DEGREE_METRES"]

DEGREE_METRES = 6_378_137.0 * math.pi / 180.0
"""Metres per degree used to carry a scale between metres and degrees (the equator of WGS 84)."""

_INT32 = (-(2**31), 2**31 - 1)
_CRS_RECORDS = {("LASF_Projection", 2111), ("LASF_Projection", 2112), ("LASF_Projection", 34735),
                ("LASF_Projection", 34736), ("LASF_Projection", 34737), ("liblas", 2112)}
_UNIT_CODES = {1.0: 9001, 0.3048: 9002, 1200 / 3937: 9003}


# --------------------------------------------------------------------------- CRS objects
def _network_off() -> None:
    """PROJ never downloads grids for lidarfx."""
    import pyproj.network

    if pyproj.network.is_network_enabled():
        pyproj.network.set_network_enabled(False)


def parse_crs(text: Any, what: str = "CRS"):
    """A ``pyproj.CRS`` from ``EPSG:2154``, ``2154``, ``EPSG:2154+5720``, WKT, PROJJSON or a PROJ
    string (a ``pyproj.CRS`` passes through); a one-line error naming ``what`` otherwise."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    if isinstance(text, CRS):
        return text
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool):
        text = f"EPSG:{int(text)}"
    if not isinstance(text, str) or not text.strip():
        raise LidarfxError(f"{what}: give a CRS such as EPSG:2154, got {text!r}")
    t = text.strip()
    if t.isdigit():
        t = f"EPSG:{t}"
    try:
        return CRS.from_user_input(t)
    except CRSError as exc:
        detail = str(exc).rsplit("proj_create: ", 1)[-1].rstrip(")") if "proj_create" in str(exc) else str(exc)
        raise LidarfxError(f"{what}: unknown CRS {text!r} ({' '.join(detail.split())})") from None


def _header_of(obj):
    from laspy import LasHeader

    header = obj if isinstance(obj, LasHeader) else getattr(obj, "header", None)
    return header if isinstance(header, LasHeader) else None


def _vertical_key(header) -> int | None:
    from laspy.vlrs.known import GeoKeyDirectoryVlr

    for v in list(header.vlrs) + list(header.evlrs or []):
        if isinstance(v, GeoKeyDirectoryVlr):
            for k in v.geo_keys:
                if k.id == 4096 and k.tiff_tag_location == 0 and 1024 <= k.value_offset <= 32766:
                    return int(k.value_offset)
    return None


def crs_of(obj, name: str | None = None):
    """The ``pyproj.CRS`` of a LAS header or of a cloud read from LAS/LAZ (None without one): the
    WKT record, else the GeoTIFF keys (EPSG code, plus the vertical CRS key when present).  A
    record PROJ cannot read is a one-line error (``name``: the file, for the message)."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    from .crs import crs_info

    header = _header_of(obj)
    if header is None:
        return None
    where = f"{name}: " if name else ""
    try:
        info = crs_info(header)
    except Exception as exc:  # noqa: BLE001 - a damaged CRS record
        raise LidarfxError(f"{where}cannot read the CRS records of the LAS header ({exc})") from None
    if not info:
        return None
    try:
        if info.get("wkt"):
            try:
                return CRS.from_wkt(info["wkt"])
            except CRSError as exc:
                if not info.get("epsg") or "geotiff" not in info.get("sources", []):
                    warnings.warn(f"{where}the WKT record is no CRS PROJ reads ({info['wkt'][:40]!r}: "
                                  f"{' '.join(str(exc).split())[:80]}); taken as no CRS", LidarfxWarning, stacklevel=3)
                    return None
        if info.get("epsg"):
            crs = CRS.from_epsg(int(info["epsg"]))
            v = _vertical_key(header)
            if v is not None:
                try:
                    crs = CRS.from_user_input(f"EPSG:{int(info['epsg'])}+{v}")
                except CRSError:
                    pass
            return crs
    except CRSError as exc:
        raise LidarfxError(f"{where}PROJ cannot read the file's CRS ({' '.join(str(exc).split())[:160]})") from None
    return None


def crs_label(crs) -> str:
    """``EPSG:2154 (RGF93 v1 / Lambert-93)``, or the name alone when there is no EPSG code."""
    if crs is None:
        return "no CRS"
    try:
        code = crs.to_epsg()
    except Exception:  # noqa: BLE001
        code = None
    if code is None and crs.is_compound:
        parts = [s.to_epsg() for s in crs.sub_crs_list]
        if all(parts):
            return f"EPSG:{'+'.join(str(p) for p in parts)} ({crs.name})"
    return f"EPSG:{code} ({crs.name})" if code else repr(crs.name)


def same_crs(a, b) -> bool:
    """Whether two CRSs are the same: equal for PROJ (axis order aside), or both identified with
    one EPSG code (an ESRI .prj beside an EPSG WKT)."""
    if a is None or b is None:
        return a is b
    try:
        if a == b or a.equals(b, ignore_axis_order=True):
            return True
        ca, cb = a.to_epsg(min_confidence=70), b.to_epsg(min_confidence=70)
        return ca is not None and ca == cb
    except Exception:  # noqa: BLE001
        return False


def same_horizontal(a, b) -> bool:
    """Whether the horizontal parts of two CRSs are the same (:func:`same_crs` of their 2-D parts)."""
    return same_crs(_horizontal(a), _horizontal(b))


def _horizontal(crs):
    h = crs.sub_crs_list[0] if crs.is_compound else crs
    if len(h.axis_info) == 3:
        try:
            h = h.to_2d()
        except Exception:  # noqa: BLE001
            pass
    return h


def _vertical_unit(crs) -> float | None:
    """Metres per unit of the vertical axis (None: the CRS has none)."""
    if crs.is_compound and len(crs.sub_crs_list) > 1:
        axes = crs.sub_crs_list[1].axis_info
        return float(axes[0].unit_conversion_factor) if axes else 1.0
    if len(crs.axis_info) == 3:
        return float(crs.axis_info[2].unit_conversion_factor)
    if crs.is_vertical:
        return float(crs.axis_info[0].unit_conversion_factor)
    return None


def _horizontal_unit(crs) -> float:
    """Metres per horizontal coordinate unit; degrees count as :data:`DEGREE_METRES`."""
    h = _horizontal(crs)
    f = float(h.axis_info[0].unit_conversion_factor) if h.axis_info else 1.0
    if h.is_geographic:
        return f * 6_378_137.0  # radians per unit * metres per radian
    return f


def _has_vertical(crs) -> bool:
    return _vertical_unit(crs) is not None


# --------------------------------------------------------------------------- LAS CRS records
def _wkt(crs) -> str:
    return crs.to_wkt("WKT1_GDAL") or crs.to_wkt()


def _unit_code(factor: float) -> int | None:
    for f, code in _UNIT_CODES.items():
        if abs(factor - f) < 1e-12:
            return code
    return None


def _geotiff_vlrs(crs) -> list:
    """GeoTIFF key VLRs (directory + ASCII citation) for a CRS with EPSG codes; [] otherwise."""
    from laspy.vlrs.known import GeoAsciiParamsVlr, GeoKeyDirectoryVlr, GeoKeyEntryStruct

    h = _horizontal(crs)
    code = h.to_epsg()
    if code is None:
        return []
    citation = (crs.name.encode("ascii", "replace").decode("ascii") + "|")
    keys = [(1024, 0, 1, 1 if h.is_projected else 3 if h.is_geocentric else 2),
            (1026, 34737, len(citation), 0)]
    if h.is_projected:
        keys.append((3072, 0, 1, code))
        unit = _unit_code(float(h.axis_info[0].unit_conversion_factor)) if h.axis_info else None
        if unit:
            keys.append((3076, 0, 1, unit))
    else:
        keys += [(2048, 0, 1, code), (2054, 0, 1, 9102)]
    if crs.is_compound and len(crs.sub_crs_list) > 1:
        v = crs.sub_crs_list[1]
        vcode = v.to_epsg()
        if vcode:
            keys.append((4096, 0, 1, vcode))
            vu = _unit_code(float(v.axis_info[0].unit_conversion_factor)) if v.axis_info else None
            if vu:
                keys.append((4099, 0, 1, vu))
    directory = GeoKeyDirectoryVlr()
    hdr = directory.geo_keys_header
    hdr.key_directory_version, hdr.key_revision, hdr.minor_revision = 1, 1, 0
    hdr.number_of_keys = len(keys)
    directory.geo_keys = [GeoKeyEntryStruct(id=i, tiff_tag_location=loc, count=n, value_offset=v)
                          for i, loc, n, v in sorted(keys)]
    ascii_vlr = GeoAsciiParamsVlr()
    ascii_vlr.strings = [citation]
    return [directory, ascii_vlr]


def set_crs(header, crs) -> None:
    """Replace the CRS records of a ``laspy.LasHeader`` (in place) by ``crs``: LAS 1.4 an OGC WKT
    VLR and the WKT bit; LAS 1.0-1.3 GeoTIFF keys (when the CRS has EPSG codes) and the WKT VLR."""
    from laspy.vlrs.known import WktCoordinateSystemVlr

    for vlrs in (header.vlrs, header.evlrs if header.evlrs is not None else []):
        vlrs[:] = [v for v in vlrs if (str(getattr(v, "user_id", "")).rstrip("\x00"), int(getattr(v, "record_id", -1)))
                   not in _CRS_RECORDS]
    if crs is None:
        header.global_encoding.wkt = False
        return
    wkt_vlr = WktCoordinateSystemVlr(_wkt(crs))
    if header.version.minor >= 4:
        header.vlrs.append(wkt_vlr)
        header.global_encoding.wkt = True
    else:
        header.vlrs.extend(_geotiff_vlrs(crs))
        header.vlrs.append(wkt_vlr)


# --------------------------------------------------------------------------- the operation
def transformer(src, dst, *, ballpark: bool = False):
    """``(pyproj.Transformer, facts)`` of the best operation from ``src`` to ``dst`` (x = easting /
    longitude).  A one-line error when it needs a grid PROJ does not have here (named), or when only
    a ballpark operation exists and ``ballpark`` is False."""
    from pyproj.transformer import TransformerGroup

    _network_off()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Best transformation is not available": refused below, by name
        group = TransformerGroup(src, dst, always_xy=True, allow_ballpark=bool(ballpark))
    if not group.best_available and group.unavailable_operations:
        op = group.unavailable_operations[0]
        grids = sorted({g.short_name for g in op.grids if not g.available}) or ["(unnamed)"]
        import pyproj.datadir

        raise LidarfxError(
            f"the transformation from {crs_label(src)} to {crs_label(dst)} needs the grid {', '.join(grids)}, "
            f"which PROJ does not have on this machine (lidarfx never downloads); install it, e.g. "
            f"`projsync --file {grids[0]}`, into {pyproj.datadir.get_user_data_dir()} or PROJ_DATA")
    if not group.transformers:
        raise LidarfxError(
            f"PROJ knows no transformation from {crs_label(src)} to {crs_label(dst)} except a ballpark one "
            "(it leaves heights or a datum shift out); give --ballpark (ballpark=True) to accept it")
    t = group.transformers[0]
    acc = t.accuracy
    facts = {"operation": t.description, "accuracy_m": None if acc is None or acc < 0 else float(acc),
             "ballpark": "ballpark" in (t.description or "").lower()}
    return t, facts


def _transform(t, xyz: np.ndarray, progress: bool | None = None, block: int = 1 << 20) -> np.ndarray:
    """The transformed (n, 3) coordinates, in blocks (a bar on long work); non-finite results
    (points outside the operation's domain) are a one-line error."""
    from .progress import bar, wanted

    out = np.empty_like(xyz)
    n = len(xyz)
    with bar("reprojecting", n, wanted(progress)) as advance:
        for a in range(0, n, block):
            b = min(n, a + block)
            x, y, z = t.transform(xyz[a:b, 0], xyz[a:b, 1], xyz[a:b, 2])
            out[a:b, 0], out[a:b, 1], out[a:b, 2] = x, y, z
            advance(b - a)
    bad = ~np.isfinite(out).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise LidarfxError(f"{int(bad.sum())} of {n} points cannot be transformed (outside the area the operation "
                           f"covers), e.g. ({xyz[i, 0]:.10g}, {xyz[i, 1]:.10g}, {xyz[i, 2]:.10g})")
    return out


def _nice(v: float) -> float:
    """The largest power of ten not above ``v``."""
    return float(10.0 ** math.floor(math.log10(v) + 1e-9))


def check_scale(scale) -> np.ndarray | None:
    """``scale`` (one positive number or three) as three floats, None for None; else a one-line error."""
    if scale is None:
        return None
    try:
        s = np.atleast_1d(np.asarray(scale, dtype=np.float64))
    except (TypeError, ValueError):
        s = np.zeros(0)
    if s.ndim != 1 or len(s) not in (1, 3) or not (np.isfinite(s).all() and (s > 0).all()):
        raise LidarfxError(f"scale must be one positive number or three, got {scale!r}")
    return np.broadcast_to(s, (3,)).copy()


_check_scale = check_scale


def _offset(lo: float, hi: float, scale: float, axis: str) -> float:
    """An offset holding ``lo .. hi`` in 32-bit integers at ``scale``: the minimum rounded down to a
    whole unit, else the middle rounded; a one-line error when the extent does not fit."""
    for off in (math.floor(lo), float(round((lo + hi) / 2.0))):
        if round((lo - off) / scale) >= _INT32[0] and round((hi - off) / scale) <= _INT32[1]:
            return float(off)
    raise LidarfxError(f"the extent {hi - lo:.6g} of {axis} does not fit 32-bit LAS coordinates at the scale "
                       f"{scale:g} (at most {scale * 2**32:.6g}); give a coarser scale")


def output_frame(src_scales, src_crs, dst_crs, lo: np.ndarray, hi: np.ndarray, unchanged,
                 src_offsets=None, scale=None) -> tuple[np.ndarray, np.ndarray]:
    """Scales and offsets of reprojected coordinates spanning ``lo .. hi`` (see the module
    docstring).  ``unchanged``: per axis, whether the operation leaves it as it was (then the
    source scale and offset are kept when they still fit)."""
    src_scales = np.asarray(src_scales, dtype=np.float64)
    forced = check_scale(scale)
    hs, hd = _horizontal_unit(src_crs), _horizontal_unit(dst_crs)
    vs = _vertical_unit(src_crs) or (hs if _horizontal(src_crs).is_projected else 1.0)
    vd = _vertical_unit(dst_crs) or (hd if _horizontal(dst_crs).is_projected else 1.0)
    sxy = float(min(src_scales[0], src_scales[1]))
    scales = np.array([_nice(sxy * hs / hd), _nice(sxy * hs / hd), _nice(float(src_scales[2]) * vs / vd)])
    offsets = np.zeros(3)
    for a, name in enumerate("xyz"):
        if unchanged[a] and forced is None:
            scales[a] = src_scales[a]
            if src_offsets is not None:
                o = float(src_offsets[a])
                if round((lo[a] - o) / scales[a]) >= _INT32[0] and round((hi[a] - o) / scales[a]) <= _INT32[1]:
                    offsets[a] = o
                    continue
        if forced is not None:
            scales[a] = forced[a]
        offsets[a] = _offset(float(lo[a]), float(hi[a]), float(scales[a]), name)
    return scales, offsets


def _new_header(cloud: PointCloud):
    """A LAS 1.4 header for a cloud read from another format (the writer widens the point format
    for colours)."""
    from laspy import LasHeader

    from . import __version__

    header = LasHeader(version="1.4", point_format=6)
    header.generating_software = f"lidarfx {__version__}"
    return header


def reproject(cloud: PointCloud, to, *, source=None, scale=None, ballpark: bool = False,
              progress: bool | None = None) -> PointCloud:
    """The cloud in the CRS ``to`` (``EPSG:4326``, ``EPSG:2154+5720``, WKT, a ``pyproj.CRS``).

    ``source`` (``--from``) is the cloud's CRS when the file has none or a wrong one.  Returns a
    new cloud: transformed coordinates, the same attributes, a header with the new CRS records,
    scales and offsets (:func:`output_frame`; ``scale`` forces the scale), and
    ``meta["reproject"]``: what was done (source, target, operation, accuracy, vertical handling,
    scales, offsets).  See the module docstring for the grid, ballpark and header rules."""
    dst = parse_crs(to, "--to")
    found = crs_of(cloud, cloud.meta.get("source"))
    if source is not None:
        src = parse_crs(source, "--from")
        if found is not None and not same_horizontal(found, src):
            warnings.warn(f"the file's CRS is {crs_label(found)}; --from {crs_label(src)} is used instead",
                          LidarfxWarning, stacklevel=2)
    else:
        src = found
    if src is None:
        raise LidarfxError("the cloud has no CRS; give the one its coordinates are in with --from (e.g. --from EPSG:2154)")
    t, facts = transformer(src, dst, ballpark=ballpark)
    xyz = _transform(t, cloud.xyz, progress)
    unchanged = [bool(np.array_equal(xyz[:, a], cloud.xyz[:, a])) for a in range(3)]
    header = _header_of(cloud)
    if header is not None:
        header = header.copy()
        src_scales, src_offsets = np.asarray(header.scales), np.asarray(header.offsets)
    else:
        header = _new_header(cloud)
        src_scales, src_offsets = np.full(3, 0.001), None
    lo = xyz.min(axis=0) if len(xyz) else np.zeros(3)
    hi = xyz.max(axis=0) if len(xyz) else np.zeros(3)
    scales, offsets = output_frame(src_scales, src, dst, lo, hi, unchanged, src_offsets, scale)
    header.scales, header.offsets = scales, offsets
    set_crs(header, dst)
    out = PointCloud(xyz, cloud.attrs, header=header, meta=cloud.meta)
    out.meta["reproject"] = describe(src, dst, facts, unchanged, scales, offsets)
    note = heights_note(src, dst)
    if note:
        warnings.warn(note, LidarfxWarning, stacklevel=2)
    return out


def heights_note(src, dst) -> str | None:
    """A warning when z keeps a unit the new CRS does not use: neither CRS has a vertical axis and
    their horizontal units differ (PROJ leaves z as it is)."""
    if _has_vertical(src) or _has_vertical(dst):
        return None
    hs, hd = _horizontal(src), _horizontal(dst)
    if not (hs.is_projected and hd.is_projected):
        return None
    us, ud = _horizontal_unit(src), _horizontal_unit(dst)
    if abs(us - ud) < 1e-12:
        return None
    from .crs import unit_name

    return (f"z stays in {unit_name(us)} while x and y are now in {unit_name(ud)}: neither CRS has a vertical "
            "axis; give compound CRSs (e.g. --to EPSG:CODE+VERTICAL) to convert heights")


def describe(src, dst, facts: dict, unchanged, scales, offsets) -> dict[str, Any]:
    """The summary of a reprojection (JSON)."""
    vs, vd = _has_vertical(src), _has_vertical(dst)
    if vs and vd:
        vertical = "heights transformed" if not unchanged[2] else "heights unchanged by the operation"
    elif not vs and not vd:
        vertical = "no vertical CRS: heights unchanged"
    else:
        vertical = (f"heights unchanged: only {'the source' if vs else 'the target'} has a vertical axis"
                    if unchanged[2] else "heights transformed")
    return {"from": crs_label(src), "to": crs_label(dst), **facts, "vertical": vertical,
            "scales": [float(s) for s in scales], "offsets": [float(o) for o in offsets]}
