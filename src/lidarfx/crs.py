"""Coordinate reference systems: what a LAS header says about its CRS, and the one place for
"metres per coordinate unit of this cloud".

The unit rule (docs/conventions.md, "Coordinates and units"): every length a user gives — CLI
options and the keyword arguments of the public functions — is in **metres**; when the file's CRS
names another linear unit (US survey foot, international foot) the length is converted to that unit
before it meets the coordinates (:func:`length_to_units`).  Positions (a scanner, the ends of a
section) are coordinates and stay in the file's CRS; values attached to points (features, heights,
offsets) are in the file's unit like its coordinates; lengths in summaries and tables are metres.
A cloud without a CRS, or with a geographic one, counts as metres.

Public API
----------
:func:`crs_info`              CRS of a LAS header (WKT / GeoTIFF keys): EPSG, unit, metres per unit
:func:`cloud_crs`             the same for a cloud read from LAS/LAZ (``None`` for other formats)
:func:`unit_to_metre`         metres per coordinate unit of a cloud (1.0 for metres or unknown)
:func:`inputs_unit_to_metre`  the same for the first of several LAS/LAZ files (chunked runs)
:func:`file_unit_to_metre`    the same for a file before its points are read
:func:`length_to_units`       a length in metres in the cloud's coordinate unit
:func:`unit_name`             ``"m"``, ``"US survey ft"``, ``"ft"`` ... for messages
:func:`prj_text`              the ESRI ``.prj`` text of a CRS
"""
from __future__ import annotations

import math
import re
from typing import Any, NamedTuple

from laspy import LasHeader
from laspy.vlrs.known import GeoKeyDirectoryVlr, WktCoordinateSystemVlr

from .errors import LidarfxError

__all__ = [
    "crs_info",
    "cloud_crs",
    "unit_to_metre",
    "inputs_unit_to_metre",
    "file_unit_to_metre",
    "length_to_units",
    "check_units",
    "metres_per_unit",
    "unit_name",
    "units_summary",
    "prj_text",
    "US_SURVEY_FOOT",
    "FOOT",
    "LENGTH_RULE",
    "UNITS",
]

US_SURVEY_FOOT = 1200 / 3937
"""Metres per US survey foot."""
FOOT = 0.3048
"""Metres per international foot."""
LENGTH_RULE = "Lengths are metres; files in feet are converted."
"""The unit rule in one sentence, for ``--help`` texts."""
UNITS = ("auto", "native")
"""``units=`` of the public functions: ``"auto"`` (lengths in metres, converted for a CRS in another
unit) or ``"native"`` (lengths in the cloud's coordinate unit, as given)."""


# ---------------------------------------------------------------- LAS headers
_GEOTIFF_UNITS = {9001: ("metre", 1.0), 9002: ("foot", 0.3048), 9003: ("US survey foot", 1200 / 3937)}
_PROJECTED_CS_KEY, _GEOGRAPHIC_CS_KEY, _PROJ_LINEAR_UNITS_KEY = 3072, 2048, 3076
_MODEL_TYPE_KEY, _MODEL_GEOGRAPHIC = 1024, 2
_WKT_GEOGRAPHIC = ("GEOGCS", "GEOGCRS", "GEODCRS", "GEOCCS")
_USER_DEFINED = 32767


class _WktNode(NamedTuple):
    keyword: str
    args: list  # str (quoted), float/str (bare), or _WktNode


def _parse_wkt(text: str) -> _WktNode | None:
    """Parse WKT1/WKT2 into a tree of keyword nodes (enough to find units and IDs)."""
    pos = 0

    def skip() -> None:
        nonlocal pos
        while pos < len(text) and text[pos].isspace():
            pos += 1

    def node() -> _WktNode:
        nonlocal pos
        m = re.compile(r"[A-Za-z_][A-Za-z0-9_]*").match(text, pos)
        if not m:
            raise ValueError(f"WKT: keyword expected at {pos}")
        pos = m.end()
        skip()
        if pos >= len(text) or text[pos] not in "[(":
            raise ValueError("WKT: '[' expected")
        close = "]" if text[pos] == "[" else ")"
        pos += 1
        args: list = []
        while True:
            skip()
            ch = text[pos]
            if ch == '"':
                end = pos + 1
                while True:
                    end = text.index('"', end)
                    if text.startswith('""', end):
                        end += 2
                        continue
                    break
                args.append(text[pos + 1 : end].replace('""', '"'))
                pos = end + 1
            elif ch.isalpha() and re.compile(r"[A-Za-z_][A-Za-z0-9_]*\s*[\[(]").match(text, pos):
                args.append(node())
            else:
                m2 = re.compile(r"[^,\])]+").match(text, pos)
                token = m2.group().strip() if m2 else ""
                pos = m2.end() if m2 else pos
                try:
                    args.append(float(token))
                except ValueError:
                    args.append(token)
            skip()
            if text[pos] == ",":
                pos += 1
            elif text[pos] == close:
                pos += 1
                return _WktNode(m.group().upper(), args)
            else:
                raise ValueError(f"WKT: unexpected {text[pos]!r}")

    try:
        return node()
    except (ValueError, IndexError):
        return None


def _wkt_epsg(node: _WktNode) -> int | None:
    for arg in node.args:
        if isinstance(arg, _WktNode) and arg.keyword in ("AUTHORITY", "ID") and len(arg.args) >= 2:
            if str(arg.args[0]).upper() == "EPSG":
                try:
                    return int(float(arg.args[1]))
                except ValueError:
                    return None
    return None


def _wkt_linear_unit(node: _WktNode) -> tuple[str, float] | None:
    """(name, metres per unit) of the horizontal axes: WKT1 ``UNIT`` under the root,
    WKT2 ``LENGTHUNIT`` under the root or its ``AXIS`` nodes; ``None`` for geographic CRSs."""
    if node.keyword in ("COMPD_CS", "COMPOUNDCRS"):
        horizontal = next((a for a in node.args if isinstance(a, _WktNode)), None)
        return _wkt_linear_unit(horizontal) if horizontal else None
    if node.keyword in _WKT_GEOGRAPHIC:
        return None
    axes = [a for a in node.args if isinstance(a, _WktNode) and a.keyword == "AXIS"]
    for parent in [node, *axes]:
        for a in parent.args:
            if isinstance(a, _WktNode) and a.keyword in ("UNIT", "LENGTHUNIT") and len(a.args) >= 2:
                if isinstance(a.args[1], float):
                    return str(a.args[0]), a.args[1]
    return None


def _all_vlrs(header: LasHeader) -> list:
    return list(header.vlrs) + list(header.evlrs or [])


def crs_info(header: LasHeader) -> dict[str, Any] | None:
    """CRS of a LAS header: ``{wkt, epsg, linear_unit, unit_to_metre, geographic, sources}`` or ``None``.

    WKT (OGC WKT VLR/EVLR) wins over GeoTIFF keys.  ``epsg`` is the root
    authority code of the WKT, else the GeoTIFF projected / geographic CS key
    (``None`` when user-defined).  ``unit_to_metre`` is the horizontal unit
    (``None`` for geographic coordinates or when unknown); ``geographic`` is
    true for longitude/latitude coordinates; ``sources`` lists the CRS records
    found (``"wkt"``, ``"geotiff"``).
    """
    vlrs = _all_vlrs(header)
    wkts = [v.string.strip("\x00 \r\n") for v in vlrs if isinstance(v, WktCoordinateSystemVlr)]
    wkt = next((w for w in wkts if w), None)
    keys: dict[int, int] = {}
    for v in vlrs:
        if isinstance(v, GeoKeyDirectoryVlr):
            direct = (k for k in v.geo_keys if k.tiff_tag_location == 0 and k.id)  # value stored in the key
            keys.update({int(k.id): int(k.value_offset) for k in direct})
    if wkt is None and not keys:
        return None
    epsg, unit = None, None
    tree = _parse_wkt(wkt) if wkt else None
    if tree is not None:
        epsg, unit = _wkt_epsg(tree), _wkt_linear_unit(tree)
        geographic = tree.keyword in _WKT_GEOGRAPHIC
    else:
        geographic = keys.get(_MODEL_TYPE_KEY) == _MODEL_GEOGRAPHIC
    if epsg is None:
        for key in (_PROJECTED_CS_KEY, _GEOGRAPHIC_CS_KEY):
            code = keys.get(key)
            if code and code != _USER_DEFINED:
                epsg = code
                break
    if unit is None and tree is None:
        unit = _GEOTIFF_UNITS.get(keys.get(_PROJ_LINEAR_UNITS_KEY, -1))
    return {
        "wkt": wkt,
        "epsg": epsg,
        "linear_unit": unit[0] if unit else None,
        "unit_to_metre": unit[1] if unit else None,
        "geographic": geographic,
        "sources": [k for k, found in (("wkt", wkt), ("geotiff", keys)) if found],
    }


# ---------------------------------------------------------------- clouds and lengths
def cloud_crs(cloud: Any) -> dict[str, Any] | None:
    """``{"wkt", "epsg", "geographic", "unit_to_metre"}`` from a cloud's LAS header (or of a
    ``laspy.LasHeader``), else ``None``."""
    header = cloud if isinstance(cloud, LasHeader) else getattr(cloud, "header", None)
    if header is None or not isinstance(header, LasHeader):
        return None
    try:
        info = crs_info(header)
    except Exception:  # a header we cannot read must not stop the work
        return None
    if not info:
        return None
    return {
        "wkt": info.get("wkt"),
        "epsg": info.get("epsg"),
        "geographic": bool(info.get("geographic")),
        "unit_to_metre": info.get("unit_to_metre"),
    }


def _positive(u: Any) -> float:
    try:
        u = float(u)
    except (TypeError, ValueError):
        return 1.0
    return u if math.isfinite(u) and u > 0 else 1.0


def unit_to_metre(cloud: Any) -> float:
    """Metres per coordinate unit of ``cloud`` (or of a ``laspy.LasHeader``) from its LAS
    header's CRS: 0.3048006 for US survey feet, 0.3048 for feet, 1.0 for metres, a geographic
    CRS, no CRS or a cloud not read from LAS.  A number is taken as that factor (so a caller may
    pass the unit itself)."""
    if cloud is None:
        return 1.0
    if isinstance(cloud, (int, float)) and not isinstance(cloud, bool):
        return _positive(cloud)
    return _positive((cloud_crs(cloud) or {}).get("unit_to_metre"))


def inputs_unit_to_metre(inputs: Any) -> float:
    """Metres per coordinate unit of the first LAS/LAZ file of ``inputs`` (a file, several, or a
    folder of tiles); 1.0 for metres or a CRS that cannot be read."""
    from .io.las import read_header
    from .tiles.catalog import expand_inputs

    try:
        info = crs_info(read_header(expand_inputs(inputs)[0])) or {}
    except LidarfxError:
        raise
    except Exception:  # a CRS we cannot read: metres, as the in-memory run assumes
        return 1.0
    return _positive(info.get("unit_to_metre"))


def file_unit_to_metre(path: Any) -> float:
    """Metres per coordinate unit of a point-cloud file before reading its points: from the header
    of a LAS/LAZ file, 1.0 for other formats (they carry no CRS) or a CRS that cannot be read."""
    from pathlib import Path

    if Path(path).suffix.lower() not in (".las", ".laz"):
        return 1.0
    from .io.las import read_header

    try:
        return unit_to_metre(read_header(Path(path)))
    except Exception:  # the reader's own error comes when the points are read
        return 1.0


def check_units(units: Any) -> str:
    """``units`` of a public function: ``"auto"`` or ``"native"`` (:data:`UNITS`)."""
    if units not in UNITS:
        raise LidarfxError(f"units must be 'auto' (lengths in metres) or 'native' (coordinate units), got {units!r}")
    return units


def metres_per_unit(cloud: Any, units: str = "auto") -> float:
    """:func:`unit_to_metre` of ``cloud`` for ``units="auto"``, 1.0 for ``units="native"``."""
    return unit_to_metre(cloud) if check_units(units) == "auto" else 1.0


def length_to_units(cloud: Any, metres: Any, units: str = "auto") -> Any:
    """A length in metres in the coordinate unit of ``cloud`` (a cloud, or its metres per unit):
    ``metres / unit_to_metre(cloud)``.  ``None`` and what is not a number (the caller's checks
    refuse it) come back unchanged, and so does every value with ``units="native"``."""
    if metres is None or isinstance(metres, bool):
        return metres
    try:
        v = float(metres)
    except (TypeError, ValueError):
        return metres
    u = metres_per_unit(cloud, units)
    return metres if u == 1.0 else v / u


def unit_name(cloud: Any) -> str:
    """The coordinate unit of ``cloud`` (or of a metres-per-unit number) for messages: ``"m"``,
    ``"US survey ft"``, ``"ft"``, else ``"unit of 0.9144 m"``."""
    u = unit_to_metre(cloud)
    if abs(u - 1.0) < 1e-12:
        return "m"
    if abs(u - US_SURVEY_FOOT) < 1e-12:
        return "US survey ft"
    if abs(u - FOOT) < 1e-12:
        return "ft"
    return f"unit of {u:.10g} m"


def units_summary(cloud: Any) -> dict[str, Any]:
    """What a JSON summary says about units: ``{"lengths": "m", "coordinates": "US survey ft",
    "unit_to_metre": 0.3048006...}`` (lengths of the summary in metres, coordinates in the file's
    unit)."""
    return {"lengths": "m", "coordinates": unit_name(cloud), "unit_to_metre": unit_to_metre(cloud)}


def prj_text(crs: dict | None) -> str | None:
    """The ``.prj`` of an ESRI grid or shapefile: ESRI WKT1 of the CRS (from its WKT or EPSG code,
    by pyproj), the WKT as it is when pyproj cannot convert it, None without a CRS."""
    crs = crs or {}
    wkt, epsg = crs.get("wkt"), crs.get("epsg")
    if not wkt and not epsg:
        return None
    try:
        from pyproj import CRS
        from pyproj.enums import WktVersion

        return CRS.from_user_input(wkt or int(epsg)).to_wkt(WktVersion.WKT1_ESRI)
    except Exception:  # an unusual WKT pyproj does not read: written as the file has it
        return wkt or None
