"""One self-contained HTML report page with an interactive 3-D viewer.

>>> from lidarfx.report import Report
>>> rep = Report("Corridor 12", command="lidarfx powerlines corridor.laz out/")   # doctest: +SKIP
>>> rep.add_summary({"points": len(cloud), "wires": 6})                           # doctest: +SKIP
>>> rep.add_cloud(cloud, labels={"classification": {14: "wire"}})                 # doctest: +SKIP
>>> rep.add_lines("wires", [w.xyz for w in wires], properties=[w.info for w in wires])  # doctest: +SKIP
>>> rep.write("out/report")                                                       # doctest: +SKIP
PosixPath('out/report/index.html')

The page is one file: the viewer (three.js bundled at build time, see
``viewer/`` and docs/report.md) and the data are inlined, so it opens from
``file://`` without a network.  Points and lines are base64 blocks in the page
(:mod:`lidarfx.report._encode` describes the encoding).
"""
from __future__ import annotations

import base64
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .._atomic import atomic_path
from ..errors import LidarfxError, check_int
from . import _encode
from ._html import CSS, esc, fmt, key_values, table

__all__ = ["Report", "viewer_attributes", "MAX_ATTRIBUTES"]

MAX_ATTRIBUTES = 16
"""Attributes put in the viewer when the caller does not choose them."""

MAX_POINTS_LIMIT = 50_000_000
"""Largest ``max_points`` (a browser holds about 30 bytes per shown point, plus the page text)."""

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def viewer_attributes(cloud, first: Sequence[str] = (), limit: int = MAX_ATTRIBUTES) -> list[str]:
    """The attributes a report shows by default: ``classification``, then ``first``, then the
    cloud's other per-point numeric attributes (those with more than one value before the
    constant ones), at most ``limit``."""
    names = [n for n in cloud.names if _encode.is_scalar_attribute(cloud[n])]
    order = [n for n in ("classification", *first) if n in names]
    rest = [n for n in names if n not in order]
    varying = [n for n in rest if _varies(cloud[n])]
    order += varying + [n for n in rest if n not in varying]
    return order[:limit]


def _int_keys(name: str, labels: Mapping) -> dict[int, str]:
    """``labels`` with int keys (the values of a categorical attribute)."""
    try:
        return {int(k): str(v) for k, v in labels.items()}
    except (TypeError, ValueError, AttributeError):
        raise LidarfxError(f"labels of {name!r} must map integer values to names, e.g. {{2: 'ground'}}") from None


def _varies(a: np.ndarray) -> bool:
    if len(a) == 0:
        return False
    if a.dtype.kind == "f":
        ok = a[np.isfinite(a)]
        return bool(len(ok) and (ok.min() != ok.max() or len(ok) < len(a)))
    return bool(a.min() != a.max())


class Report:
    """An HTML report: key figures, one point cloud with line layers in a 3-D viewer,
    pictures, tables and links, written as ``OUTDIR/index.html``.

    ``title`` heads the page; ``command`` (the command line that made it) is shown
    under it.  ``max_points`` caps the points put in the viewer (a random subsample,
    drawn with ``seed``, when the cloud is larger).
    """

    def __init__(self, title: str, *, command: str | None = None, max_points: int = 1_000_000, seed: int = 0):
        self.title = str(title)
        self.command = command
        self.max_points = check_int("max_points", max_points, 1, MAX_POINTS_LIMIT)
        self.seed = int(seed)
        self._summary: dict[str, Any] = {}
        self._cloud: dict | None = None
        self._layers: list[dict] = []
        self._pictures: list[tuple[str, str]] = []
        self._tables: list[tuple[str, list]] = []
        self._links: list[tuple[str, str, str]] = []

    # ------------------------------------------------------------------ content
    def add_summary(self, items: Mapping[str, Any]) -> None:
        """Key figures (name -> number or text) for the table at the top; later calls add
        to it (a repeated name takes the later value in its first place)."""
        for k, v in items.items():
            self._summary[str(k)] = v

    def add_cloud(self, cloud, attributes: Sequence[str] | None = None, *,
                  labels: Mapping[str, Mapping[int, str]] | None = None, colour_by: str | None = None) -> None:
        """Put a point cloud in the viewer (one per report) and its summary on the page.

        ``attributes``: the per-point attributes to carry (colour choices and the
        values shown when a point is picked); None takes :func:`viewer_attributes`
        and the page names the ones left out.  ``labels`` names categorical values,
        e.g. ``{"classification": {2: "ground"}}`` (classification defaults to the
        ASPRS names).  ``colour_by``: the attribute shown first (an attribute,
        ``z`` or ``rgb``; default classification if present, else z).

        Points with non-finite coordinates are not drawn.  Clouds above
        ``max_points`` are subsampled at random (seeded); picking then reports the
        point's index in the whole cloud.
        """
        from ..cloud import PointCloud
        from ..io import ASPRS_CLASSES

        if self._cloud is not None:
            raise LidarfxError("a report holds one point cloud; add_cloud was called twice")
        if not isinstance(cloud, PointCloud):
            raise LidarfxError("add_cloud expects a PointCloud (see lidarfx.read)")
        if attributes is None:
            chosen = viewer_attributes(cloud)
        else:
            chosen = list(dict.fromkeys(str(a) for a in attributes))
            for name in chosen:
                if name not in cloud:
                    avail = ", ".join(cloud.names) or "none"
                    raise LidarfxError(f"unknown attribute {name!r}; available: {avail}")
                if not _encode.is_scalar_attribute(cloud[name]):
                    raise LidarfxError(f"attribute {name!r} is not a per-point number; the viewer shows numbers only")
        colour_choices = [*chosen, "z"] + (["rgb"] if {"red", "green", "blue"} <= set(chosen) else [])
        if colour_by is None:
            colour_by = "classification" if "classification" in chosen else "z"
        elif colour_by not in colour_choices:
            raise LidarfxError(f"colour_by {colour_by!r} is not among the viewer's attributes: "
                               f"{', '.join(colour_choices)}")
        all_labels = {str(k): _int_keys(str(k), v) for k, v in (labels or {}).items()}
        if "classification" in chosen:
            all_labels["classification"] = {**ASPRS_CLASSES, **all_labels.get("classification", {})}

        n = len(cloud)
        finite = np.all(np.isfinite(cloud.xyz), axis=1)
        valid = np.flatnonzero(finite) if not finite.all() else None
        n_valid = int(finite.sum())
        rng = np.random.default_rng(self.seed)
        if n_valid > self.max_points:
            pick = np.sort(rng.choice(n_valid, self.max_points, replace=False))
            shown = pick if valid is None else valid[pick]
        else:
            shown = valid if valid is not None else None  # None: every point, in order
        xyz = cloud.xyz if shown is None else cloud.xyz[shown]
        n_shown = len(xyz)
        if n_valid:
            lo, hi = cloud.xyz[finite].min(axis=0), cloud.xyz[finite].max(axis=0)
        else:
            lo = hi = np.zeros(3)
        centre = _encode.rounded_centre(lo, hi)
        blocks: dict[str, str] = {}
        specs = []
        if n_shown:
            blocks["positions"] = _encode.b64((xyz - centre).astype(np.float32))
            if shown is not None:
                blocks["index"] = _encode.b64(shown.astype(np.uint32))
            for k, name in enumerate(chosen):
                values = np.asarray(cloud[name])
                values = values if shown is None else values[shown]
                spec, codes = _encode.encode_attribute(name, values, all_labels.get(name))
                spec["block"] = f"lfx-a{k}"
                blocks[spec["block"]] = _encode.b64(codes)
                specs.append(spec)
            zs = xyz[:, 2]
            zlo, zhi = np.percentile(zs, [2, 98])
        self._cloud = {
            "n": n, "n_shown": n_shown, "n_valid": n_valid, "centre": centre, "bounds": (lo, hi),
            "attributes": chosen, "specs": specs, "blocks": blocks, "colour_by": colour_by,
            "z": {"lo": float(zlo), "hi": float(zhi)} if n_shown else None,
            "left_out": [m for m in cloud.names if m not in chosen and _encode.is_scalar_attribute(cloud[m])],
            "facts": _cloud_facts(cloud, lo, hi, n_valid),
            "attribute_rows": _attribute_rows(cloud, set(chosen)),
        }

    def add_lines(self, name: str, lines: Sequence[np.ndarray], *, colour: str | None = None,
                  properties: Sequence[Mapping[str, Any]] | None = None) -> None:
        """A named, toggleable layer of 3-D polylines (``(k, 3)`` arrays of absolute
        coordinates, k >= 2) in the viewer, with one ``properties`` dict per line shown
        when the line is picked and as a table under the viewer.  ``colour``: a CSS hex
        colour (``#rrggbb``; default: the next of a fixed set)."""
        arrs = []
        for i, ln in enumerate(lines):
            a = np.asarray(ln, dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != 3 or len(a) < 2:
                raise LidarfxError(f"layer {name!r}: line {i + 1} must be a (k, 3) array with k >= 2, "
                                   f"got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise LidarfxError(f"layer {name!r}: line {i + 1} has non-finite coordinates")
            arrs.append(a.copy())
        if properties is not None and len(properties) != len(arrs):
            raise LidarfxError(f"layer {name!r}: {len(properties)} property rows for {len(arrs)} lines")
        if colour is not None and not (isinstance(colour, str) and len(colour) == 7 and colour.startswith("#")
                                       and all(c in "0123456789abcdefABCDEF" for c in colour[1:])):
            raise LidarfxError(f"layer {name!r}: colour must be #rrggbb, got {colour!r}")
        self._layers.append({"name": str(name), "lines": arrs, "colour": colour,
                             "properties": [dict(p) for p in properties] if properties is not None else None})

    def add_picture(self, picture: str | Path | bytes, caption: str) -> None:
        """Embed a PNG (a file path or the bytes) with a caption."""
        if isinstance(picture, (bytes, bytearray, memoryview)):
            data, what = bytes(picture), "picture bytes"
        else:
            path = Path(picture)
            if not path.is_file():
                raise LidarfxError(f"picture {path}: no such file")
            data, what = path.read_bytes(), f"picture {path}"
        if not data.startswith(PNG_SIGNATURE):
            raise LidarfxError(f"{what}: not a PNG file")
        self._pictures.append((base64.b64encode(data).decode("ascii"), str(caption)))

    def add_table(self, title: str, rows: Sequence[Mapping[str, Any]]) -> None:
        """A titled table of dict rows (columns: the union of the keys in order; floats
        to 6 significant digits, NaN and ±inf empty)."""
        self._tables.append((str(title), [dict(r) for r in rows]))

    def add_link(self, title: str, href: str, note: str = "") -> None:
        """A link (e.g. to another report's ``index.html``, relative to this page)."""
        self._links.append((str(title), str(href), str(note)))

    @property
    def cloud_summary(self) -> dict[str, Any] | None:
        """What :meth:`add_cloud` put in the page: ``points``, ``shown`` (points in the
        viewer), ``attributes`` (carried by the viewer), ``left_out`` (numeric attributes
        not carried), ``colour_by`` and ``centre`` (of the viewer's float32 offsets);
        None before :meth:`add_cloud`."""
        c = self._cloud
        if c is None:
            return None
        return {"points": c["n"], "shown": c["n_shown"], "attributes": list(c["attributes"]),
                "left_out": list(c["left_out"]), "colour_by": c["colour_by"], "centre": c["centre"].tolist()}

    # -------------------------------------------------------------------- output
    def write(self, outdir: str | Path) -> Path:
        """Write ``outdir/index.html`` (creating ``outdir``) through a temporary file
        renamed at the end, and return its path."""
        out = Path(outdir)
        if out.exists() and not out.is_dir():
            raise LidarfxError(f"{out} exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
        target = out / "index.html"
        with atomic_path(target) as tmp:
            with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
                for part in self._parts():
                    fh.write(part)
        return target

    # ------------------------------------------------------------------- the page
    def _centre(self) -> np.ndarray:
        if self._cloud is not None and self._cloud["n_shown"]:
            return self._cloud["centre"]
        verts = [ln for layer in self._layers for ln in layer["lines"]]
        if not verts:
            return np.zeros(3)
        allv = np.concatenate(verts)
        return _encode.rounded_centre(allv.min(axis=0), allv.max(axis=0))

    def _meta(self, centre: np.ndarray) -> tuple[dict, dict[str, str]]:
        """The viewer's JSON description and the base64 blocks it names."""
        blocks: dict[str, str] = {}
        cloud = None
        c = self._cloud
        if c is not None and c["n_shown"]:
            blocks["lfx-xyz"] = c["blocks"]["positions"]
            if "index" in c["blocks"]:
                blocks["lfx-index"] = c["blocks"]["index"]
            for spec in c["specs"]:
                blocks[spec["block"]] = c["blocks"][spec["block"]]
            lo, hi = c["bounds"]
            cloud = {"n_total": c["n"], "n_shown": c["n_shown"], "positions": "lfx-xyz",
                     "index": "lfx-index" if "index" in c["blocks"] else None,
                     "bounds": {"min": lo.tolist(), "max": hi.tolist()}, "colour_by": c["colour_by"],
                     "attributes": c["specs"], "z": c["z"]}
        layers = []
        for k, layer in enumerate(self._layers):
            spans, verts = _encode.encode_lines(layer["lines"], centre)
            bid = f"lfx-l{k}"
            blocks[bid] = _encode.b64(verts)
            props = ([{str(p): fmt(v) for p, v in row.items()} for row in layer["properties"]]
                     if layer["properties"] is not None else None)
            layers.append({"name": layer["name"], "colour": layer["colour"], "block": bid, "lines": spans,
                           "properties": props})
        meta = {"version": 1, "centre": centre.tolist(), "cloud": cloud, "layers": layers}
        return meta, blocks

    def _parts(self):
        """The page as a sequence of strings (the data blocks are large: never joined)."""
        from .. import __version__, _json

        has_view = (self._cloud is not None and self._cloud["n_shown"] > 0) or bool(self._layers)
        yield ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
               "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
               f"<meta name=\"generator\" content=\"lidarfx {esc(__version__)}\">\n"
               f"<title>{esc(self.title)}</title>\n<style>{CSS}</style>\n")
        if has_view:
            # errors of the viewer are collected for tests and diagnosis before it runs
            yield ("<script>window.lidarfxViewer={ready:false,errors:[]};"
                   "window.addEventListener('error',function(e){window.lidarfxViewer.errors.push("
                   "String(e.message||e))});window.addEventListener('unhandledrejection',function(e){"
                   "window.lidarfxViewer.errors.push(String(e.reason))});</script>\n")
        yield "</head>\n<body>\n<main>\n"
        yield f"<h1>{esc(self.title)}</h1>\n"
        if self.command:
            yield f'<pre class="command"><code>{esc(self.command)}</code></pre>\n'
        if self._summary:
            yield f"<section id=\"summary\"><h2>Summary</h2>{key_values(self._summary)}</section>\n"
        c = self._cloud
        if has_view:
            centre = self._centre()
            meta, blocks = self._meta(centre)
            yield "<section id=\"view\"><h2>3-D view</h2>\n<div id=\"lidarfx-viewer\" class=\"lfx-viewer\">"
            yield "<p class=\"lfx-nowebgl\">The 3-D view needs JavaScript.</p></div>\n"
            if c is not None and c["n_shown"] < c["n_valid"]:
                yield (f"<p class=\"note\">{c['n_shown']:,} of {c['n_valid']:,} points shown "
                       f"(random subsample, seed {self.seed}).</p>\n")
            if c is not None and c["left_out"]:
                yield (f"<p class=\"note\">Not in the viewer: {esc(', '.join(c['left_out']))} "
                       f"(the viewer carries {len(c['attributes'])} attributes).</p>\n")
            yield "</section>\n"
            yield ("<script type=\"application/json\" id=\"lidarfx-meta\">"
                   + _json.dumps(meta).replace("</", "<\\/") + "</script>\n")
            for bid, text in blocks.items():
                yield f"<script type=\"application/octet-stream\" id=\"{bid}\">"
                yield text
                yield "</script>\n"
        for layer in self._layers:
            yield self._layer_table(layer)
        if c is not None:
            yield "<section id=\"cloud\"><h2>Point cloud</h2>" + key_values(c["facts"])
            yield "<h3>Attributes</h3>" + table(c["attribute_rows"]) + "</section>\n"
        if self._pictures:
            yield "<section id=\"pictures\"><h2>Pictures</h2>\n"
            for data, caption in self._pictures:
                yield (f"<figure><img alt=\"{esc(caption)}\" src=\"data:image/png;base64,{data}\">"
                       f"<figcaption>{esc(caption)}</figcaption></figure>\n")
            yield "</section>\n"
        for title, rows in self._tables:
            yield f"<section class=\"table\"><h2>{esc(title)}</h2>"
            yield (table(rows) if rows else "<p class=\"note\">No rows.</p>") + "</section>\n"
        if self._links:
            yield "<section id=\"links\"><h2>Links</h2><ul class=\"links\">"
            for title, href, note in self._links:
                yield (f"<li><a href=\"{esc(href)}\">{esc(title)}</a>"
                       + (f" <span class=\"note\">{esc(note)}</span>" if note else "") + "</li>")
            yield "</ul></section>\n"
        stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        credit = " · 3-D view: three.js (MIT licence)" if has_view else ""
        yield f"<footer>lidarfx {esc(__version__)} · {stamp}{credit}</footer>\n</main>\n"
        if has_view:
            yield "<script>" + _bundle() + "</script>\n"
        yield "</body>\n</html>\n"

    def _layer_table(self, layer: dict) -> str:
        lines = layer["lines"]
        rows = []
        for i, ln in enumerate(lines):
            row: dict[str, Any] = {"line": i + 1}
            if layer["properties"] is not None:
                row.update(layer["properties"][i])
            else:
                row["vertices"] = len(ln)
                row["length"] = float(np.linalg.norm(np.diff(ln, axis=0), axis=1).sum())
            rows.append(row)
        body = table(rows) if rows else "<p class=\"note\">No lines.</p>"
        return f"<section class=\"layer\"><h2>{esc(layer['name'])} ({len(lines):,} lines)</h2>{body}</section>\n"


def _bundle() -> str:
    """The viewer script (three.js + the viewer, built by ``npm run build`` in viewer/)."""
    try:
        text = resources.files(__package__).joinpath("assets/viewer.min.js").read_text(encoding="utf-8")
    except FileNotFoundError:
        raise LidarfxError("the report viewer bundle is missing from the installation "
                           "(build it: cd viewer && npm ci && npm run build)") from None
    return text.replace("</script", "<\\/script")


def _crs_text(cloud) -> str | None:
    """The CRS as one line: ``EPSG:n`` and the name from its WKT, or what ``cloud.crs`` /
    ``cloud.meta["crs"]`` hold."""
    crs = getattr(cloud, "crs", None) or cloud.meta.get("crs")
    if crs is None and cloud.header is not None:
        from ..io import las

        if isinstance(cloud.header, las.LasHeader):
            crs = las.crs_info(cloud.header)
    if crs is None:
        return None
    if isinstance(crs, Mapping):
        parts = []
        if crs.get("epsg"):
            parts.append(f"EPSG:{crs['epsg']}")
        wkt = crs.get("wkt") or ""
        if '"' in wkt:
            parts.append(wkt.split('"')[1])
        if crs.get("linear_unit"):
            parts.append(f"unit {crs['linear_unit']}")
        return ", ".join(parts) or "user-defined"
    to_string = getattr(crs, "to_string", None)
    text = to_string() if callable(to_string) else str(crs)
    return text if len(text) <= 300 else text[:297] + "..."


def _cloud_facts(cloud, lo: np.ndarray, hi: np.ndarray, n_valid: int) -> dict[str, Any]:
    facts: dict[str, Any] = {}
    src = cloud.meta.get("source") or cloud.meta.get("name")
    if src:
        facts["file"] = src
    facts["points"] = f"{len(cloud):,}"
    if n_valid < len(cloud):
        facts["points with finite coordinates"] = f"{n_valid:,}"
    if n_valid:
        facts["x range"] = f"{fmt(lo[0])} .. {fmt(hi[0])}"
        facts["y range"] = f"{fmt(lo[1])} .. {fmt(hi[1])}"
        facts["z range"] = f"{fmt(lo[2])} .. {fmt(hi[2])}"
    facts["CRS"] = _crs_text(cloud) or "not given"
    return facts


def _attribute_rows(cloud, shown: set[str]) -> list[dict[str, Any]]:
    rows = []
    for name in cloud.names:
        a = np.asarray(cloud[name])
        row: dict[str, Any] = {"attribute": name, "type": str(a.dtype) if a.ndim == 1 else f"{a.dtype} {a.shape[1:]}"}
        if _encode.is_scalar_attribute(a) and len(a):
            v = a.astype(np.float64) if a.dtype.kind == "b" else a
            ok = np.isfinite(v) if v.dtype.kind == "f" else None
            fv = v if ok is None else v[ok]
            row["min"] = fv.min() if len(fv) else None
            row["max"] = fv.max() if len(fv) else None
            row["no value"] = int(len(a) - len(fv))
        row["in viewer"] = "yes" if name in shown else ""
        rows.append(row)
    return rows
