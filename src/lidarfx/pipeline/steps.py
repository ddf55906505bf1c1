"""The step registry: every step a pipeline may hold, as one :class:`~.spec.Step` entry.

A step calls the library function its command calls (``lidarfx ground`` →
:func:`lidarfx.ground.classify_ground`, …) with the command's options, named as the command's
long options.  Adding a step is one entry in :data:`STEPS` plus its ``run`` function; the
documentation (docs/pipelines.md) is generated from the entries.

Defaults are written out here (the module imports no numeric code, so ``lidarfx --help`` stays
fast); ``tests/test_pipeline.py`` checks them against the commands' own defaults.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import LidarfxError
from .spec import Key, Step


@dataclass
class Context:
    """What a step's ``run`` gets besides the cloud and its options: ``progress`` (None: bars
    on a terminal; False: none), ``prepared`` (what the step's ``prepare`` loaded) and
    ``source`` (the input's name, for titles)."""

    progress: bool | None = None
    prepared: Any = None
    source: str = "cloud"


def _name(ctx: Context) -> str:
    return Path(ctx.source).name


def _points(cloud) -> dict:
    return {"points": len(cloud)}


# ============================================================================ keys shared by steps
SMRF = (
    Key("cell", "length", 1.5, "grid cell of the ground filter"),
    Key("slope", "number", 0.2, "opening slope (rise / run)"),
    Key("window", "length", 21.0, "largest opening radius"),
    Key("threshold", "length", 0.4, "final elevation threshold"),
    Key("scalar", "length", 1.5, "threshold per unit DTM slope"),
    Key("edge_step", "length", 1.0, "step height on object boundaries"),
    Key("edge_share", "number", 0.15, "boundary share of steps to stay an object (0 = plain SMRF)"),
    Key("all_returns", "bool", False, "use every return, not only last returns"),
    Key("ignore_classes", "codes", [7, 18, 66], "classes never used nor made ground (\"none\" for none)"),
)
SMRF_NAMES = ("cell", "slope", "window", "threshold", "scalar", "edge_step", "edge_share")
PICTURE = Key("picture", "output", None, "also draw a picture into this PNG", suffixes=(".png",))
RASTER = (".tif", ".tiff", ".asc")
LINES = (".geojson", ".json")


def _smrf(o: dict) -> dict:
    return {**{k: o[k] for k in SMRF_NAMES}, "last_returns": not o["all_returns"]}


def _check_smrf(o: dict) -> None:
    from ..ground import check_ignore_classes, check_params

    check_params({k: o[k] for k in SMRF_NAMES})
    check_ignore_classes(o["ignore_classes"])


def _raster_outputs(path: str | None) -> list[tuple[str, str]]:
    """A raster and what is written beside it: the .prj of an ESRI grid, the world file of the
    built-in GeoTIFF writer (without rasterio)."""
    import importlib.util

    if not path:
        return []
    out = [(path, "file")]
    if Path(path).suffix.lower() == ".asc":
        out.append((str(Path(path).with_suffix(".prj")), "file"))
    elif importlib.util.find_spec("rasterio") is None:
        out.append((str(Path(path).with_suffix(".tfw")), "file"))
    return out


def _picture(o: dict) -> list[tuple[str, str]]:
    return [(o["picture"], "file")] if o.get("picture") else []


# ============================================================================ read / write
def run_read(cloud, o, ctx):
    from .. import io

    out = io.read(o["path"], columns=o["columns"], progress=ctx.progress)
    out.meta["name"] = o["path"]  # messages name the file as written in the pipeline
    return out, {**_points(out), "note": f"{len(out):,} points from {o['path']}"}


WRITE_OPTIONS = ("point_format", "scale", "ascii", "precision", "delimiter", "compressed")


def write_options(o: dict) -> dict:
    """The format options given to a write step; a one-line error for those its format does not take."""
    import inspect

    from .. import io

    if not Path(o["path"]).suffix:  # a folder (one file per input tile) in chunks; in memory Pipeline.check refuses it
        given = [k for k in WRITE_OPTIONS if o.get(k) is not None]
        if given:
            raise LidarfxError(f"{given[0]} is not an option of a folder output")
        return {}
    module = io._format_module(Path(o["path"]))
    allowed = [n for n, p in inspect.signature(module.write).parameters.items()
               if p.kind is inspect.Parameter.KEYWORD_ONLY and n not in ("ext", "progress", "fill")]
    given = {k: o[k] for k in WRITE_OPTIONS if o.get(k) is not None}
    bad = sorted(set(given) - set(allowed))
    if bad:
        raise LidarfxError(f"{', '.join(bad)} is not an option of {Path(o['path']).suffix} output "
                           f"(options: {', '.join(allowed) or 'none'})")
    return given


def run_write(cloud, o, ctx):
    import numpy as np

    from .. import io

    opts = write_options(o)
    info: dict = {"output": o["path"], "points": len(cloud)}
    if Path(o["path"]).suffix.lower() in (".las", ".laz") and "point_format" not in opts:
        from ..io.las import format_for_classes

        # as lidarfx classify predict: class codes above 31 need a LAS 1.4 point format
        top = int(cloud.meta.get("max_class_code") or 0)
        if "classification" in cloud and len(cloud):
            top = max(top, int(np.max(cloud["classification"])))
        pf = format_for_classes(cloud.header, top)
        if pf is not None:
            opts["point_format"] = pf
            info["upgraded_point_format"] = pf
    io.write(cloud, o["path"], progress=ctx.progress, **opts)
    info["note"] = f"{len(cloud):,} points -> {o['path']}" + (
        f" (LAS 1.4 point format {opts['point_format']} for class codes above 31)"
        if "upgraded_point_format" in info else "")
    return cloud, info


# ============================================================================ cloud -> cloud
def run_ground(cloud, o, ctx):
    from ..ground import apply_ground_classification, classify_ground, dtm, height_above_ground

    params = _smrf(o)
    mask = classify_ground(cloud, ignore_classes=o["ignore_classes"], progress=ctx.progress, **params)
    out = apply_ground_classification(cloud, mask, ignore_classes=o["ignore_classes"], **params)
    if o["hag"]:
        out["height_above_ground"] = height_above_ground(out, mask)
    info = {**_points(out), "ground_points": int(mask.sum())}
    if o["dtm"]:
        if not mask.any():
            raise LidarfxError("no ground point found: no DTM written")
        raster = dtm(out, o["resolution"], ground=mask)
        raster.write(o["dtm"])
        info["dtm"] = {"path": o["dtm"], "shape": list(raster.shape)}
    info["note"] = f"{int(mask.sum()):,} of {len(out):,} points ground" + (" + height_above_ground" if o["hag"] else "") \
        + (f", DTM -> {o['dtm']}" if o["dtm"] else "")
    return out, info


def check_ground(o):
    from ..ground.dtm import check_resolution

    _check_smrf(o)
    check_resolution(o["resolution"])


def run_features(cloud, o, ctx):
    from ..features import compute_features

    out = compute_features(cloud, _feature_list(o), radii=o["radius"] or [], neighbourhood=o["neighbourhood"],
                           k=o["k"], scanner=o["scanner"], height=o["height"], convention=o["convention"],
                           d_max=o["d_max"], hist_bins=o["bins"], seed=o["seed"], progress=ctx.progress)
    names = out.meta.get("features", [])
    radii = ", ".join(f"{r:g}" for r in o["radius"] or [])
    return out, {**_points(out), "features": names, "warnings": out.meta.get("feature_warnings", []),
                 "note": f"{len(names)} features" + (f", r = {radii} m" if radii else "")}


def _feature_list(o: dict):
    return o["features"] if o["features"] is None else ",".join(o["features"])


def check_features(o):
    from ..features.api import check_options, radii_list
    from ..features.registry import resolve

    if o["neighbourhood"] != "knn" and not o["radius"]:
        raise LidarfxError('give a radius: "radius": 0.5 (a list for several scales)')
    req = resolve(_feature_list(o))
    rs = radii_list(None, o["radius"] or []) if req.slots else []
    check_options(req, rs, o["neighbourhood"], o["k"], o["convention"], o["bins"], o["height"], d_max=o["d_max"],
                  seed=o["seed"], scanner=o["scanner"])


def run_classify(cloud, o, ctx):
    import numpy as np

    model = ctx.prepared
    if o["precomputed"]:
        model.features.precomputed = True
    if o["ground"]:
        model.features.ground = o["ground"]
    model.check(cloud, str(cloud.meta.get("name") or ctx.source))
    if o["min_building_area"] is not None:
        model.set_min_building_area(o["min_building_area"])
    if o["max_multi_return_share"] is not None:
        model.set_max_multi_return_share(o["max_multi_return_share"])
    out = model.classify(cloud, confidence=o["confidence"], probabilities=o["probabilities"], progress=ctx.progress)
    # a LAS write step afterwards stores codes up to the model's highest (lidarfx classify predict does)
    out.meta["max_class_code"] = max(int(out.meta.get("max_class_code") or 0),
                                     max(int(c) for c in model.classes.codes))
    cls = np.asarray(out["classification"])
    if o["picture"]:
        from ..classify import usable_mask
        from ..classify.pipeline import unit_to_metre
        from ..render import class_map

        idx = np.where(usable_mask(out), model.classes.index_of(cls), -1)
        u = unit_to_metre(out)
        class_map(out.xyz[:, :2] * u, out.xyz[:, 2] * u, idx, list(model.classes.names), o["picture"],
                  title=f"{_name(ctx)} classified with {Path(o['model']).name}")
    counts = {int(c): int(n) for c, n in zip(*np.unique(cls, return_counts=True))}
    return out, {**_points(out), "predicted": int(out.meta["classify"]["predicted_points"]), "classes": counts,
                 "note": ", ".join(f"class {c} {n:,}" for c, n in counts.items())}


def check_classify(o):
    from ..classify.objects import check_area, check_share

    if o["min_building_area"] is not None:
        check_area(o["min_building_area"])
    if o["max_multi_return_share"] is not None:
        check_share(o["max_multi_return_share"])


def classify_inputs(o):
    return [] if o["model"] == "default" else [o["model"]]


def prepare_classify(o, job):
    from ..classify import load_model

    return load_model(o["model"])  # refused here (not trusted, not a model) before any step runs


def run_select(cloud, o, ctx):
    from ..select import evaluate, parse

    mask = evaluate(cloud, parse(o["where"]))
    if o["invert"]:
        mask = ~mask
    out = cloud.subset(mask)
    return out, {"points": len(out), "kept": len(out), "total": len(cloud),
                 "note": f"kept {len(out):,} of {len(cloud):,} points"}


def check_select(o):
    from ..select import parse

    parse(o["where"])


def run_thin(cloud, o, ctx):
    from ..thin import thin_cloud

    out = cloud.subset(thin_cloud(cloud, o["cell"], o["keep"], o["seed"]))
    return out, {"points": len(out), "kept": len(out), "total": len(cloud),
                 "note": f"kept {len(out):,} of {len(cloud):,} points, one per {o['cell']:g} m cell"}


def check_thin(o):
    from ..errors import check_seed
    from ..thin import check_cell, check_keep

    check_cell(o["cell"])
    check_keep(o["keep"])
    check_seed(o["seed"])


def run_colour(cloud, o, ctx):
    import numpy as np

    from ..colour import colour_cloud, colour_picture

    by = o["by"].strip()
    out = colour_cloud(cloud, by, radius=o["radius"], scanner=o["scanner"], sun_azimuth=o["sun_azimuth"],
                       sun_altitude=o["sun_altitude"], cmap=o["cmap"], value_range=o["range"], progress=ctx.progress)
    if o["picture"]:
        rgb = np.column_stack([out["red"], out["green"], out["blue"]])
        colour_picture(out, rgb, o["picture"], view=o["view"], title=f"{_name(ctx)}: colour by {by}")
    return out, {**_points(out), "colour": out.meta.get("colour"), "note": f"red, green, blue by {by}"}


def check_colour(o):
    from ..colour import check_cmap, check_radius, check_sun, check_value_range

    if not o["by"].strip():
        raise LidarfxError("by needs morphology, set, class or an attribute name")
    check_sun(o["sun_azimuth"], o["sun_altitude"])
    check_cmap(o["cmap"])
    check_value_range(o["range"])
    check_radius(o["radius"])


def run_eigenclass(cloud, o, ctx):
    from ..structures import LABELS, classify_structures

    refs, kind = ctx.prepared
    out = classify_structures(cloud, radii=o["radius"], references=refs if kind == "trained" else kind,
                              weighting=o["weighting"], reject=o["reject"], min_neighbours=o["min_neighbours"],
                              keep_signature=o["keep_signature"], progress=ctx.progress)
    meta = out.meta["structures"]
    if o["picture"]:
        import numpy as np

        from ..render import class_map

        names = [LABELS[k] for k in range(0, 8)]
        class_map(out.xyz[:, :2] - out.xyz[:, :2].min(axis=0), out.xyz[:, 2], np.asarray(out["structure"]), names,
                  o["picture"], title=f"{_name(ctx)}: structure classes, r = "
                  f"{', '.join(f'{r:g}' for r in meta['radii'])}")
    return out, {**_points(out), "radii": meta["radii"], "counts": meta["counts"],
                 "note": "r = " + ", ".join(f"{r:g}" for r in meta["radii"]) + " m; "
                 + ", ".join(f"{k} {v:,}" for k, v in meta["counts"].items() if v)}


def check_eigenclass(o):
    from ..structures import check_min_neighbours, check_reject

    check_reject(o["reject"])
    check_min_neighbours(o["min_neighbours"])
    if o["radius"]:
        from ..features.api import radii_list

        radii_list(None, o["radius"])


def references_inputs(o):
    return [] if o["references"] in ("trained", "analytic") else [o["references"]]


def prepare_eigenclass(o, job):
    from ..structures.references import resolve_references

    refs, kind = resolve_references(o["references"])
    refs.tables(kind, o["weighting"])
    return refs, kind


def _table_paths(stem: str) -> tuple[str, str]:
    for ext in (".csv", ".json"):
        if stem.lower().endswith(ext):
            stem = stem[: -len(ext)]
    return stem + ".csv", stem + ".json"


def run_segment(cloud, o, ctx):
    from ..segment import segment_planes, segments_table, write_segments_csv, write_segments_json
    from ..segment.planes import no_segments_hint

    out = segment_planes(cloud, normal_radius=o["normal_radius"], max_distance=o["max_distance"],
                         growing_radius=o["growing_radius"], max_angle=o["max_angle"], min_size=o["min_size"],
                         min_width=o["min_width"], scanner=o["scanner"], keep_features=o["keep_features"],
                         progress=ctx.progress)
    if out.meta["segmentation"]["segments"] == 0:  # as lidarfx segment: an empty segmentation is a wrong setting
        raise LidarfxError(no_segments_hint(out))
    rows = segments_table(out)
    info = {**_points(out), "segments": len(rows), "segmented_points": out.meta["segmentation"]["segmented_points"]}
    if o["table"]:
        meta = dict(out.meta["segmentation"])
        meta["input"] = ctx.source
        csv_path, json_path = _table_paths(o["table"])
        write_segments_csv(rows, csv_path)
        write_segments_json(rows, json_path, meta)
        info["table"] = [csv_path, json_path]
    if o["picture"]:
        from ..render import segment_view

        segment_view(out, o["picture"], height_panel=True, title=f"{_name(ctx)}: {len(rows)} segments")
    info["note"] = f"{len(rows):,} plane segments, {info['segmented_points']:,} points segmented"
    return out, info


def check_segment(o):
    from ..segment.planes import check_params

    check_params(o["normal_radius"], o["max_distance"], o["growing_radius"], o["max_angle"], o["min_size"],
                 o["min_width"])


def segment_outputs(o):
    out = [(p, "file") for p in _table_paths(o["table"])] if o["table"] else []
    return out + _picture(o)


def run_section(cloud, o, ctx):
    from ..section import section

    out = section(cloud, o["from"], o["to"], o["width"], o["normal"])
    return out, {"points": len(out), "total": len(cloud),
                 "note": f"{len(out):,} of {len(cloud):,} points in the {o['width']:g} m slab"}


def check_section(o):
    from ..section import section_frame

    section_frame(o["from"], o["to"], o["width"], o["normal"])


# ============================================================================ products
def _csv_path(o: dict, suffix: str = ".csv") -> str | None:
    if o["csv"] is False or o["csv"] is None:
        return None
    return str(Path(o["output"]).with_suffix(suffix)) if o["csv"] is True else o["csv"]


def _check_csv(o: dict) -> None:
    if isinstance(o["csv"], str) and Path(o["csv"]).suffix.lower() != ".csv":
        raise LidarfxError(f"csv {o['csv']}: give a table path ending in .csv (or true)")


def run_edges(cloud, o, ctx):
    from .. import io
    from ..crs import cloud_crs
    from ..edges import extract_edges
    from ..vector import export_lines

    labels = [s.strip() for s in o["labels"].split(",") if s.strip()]
    res = extract_edges(cloud, o["radius"], labels=labels, use_structure=o["use_structure"],
                        references=o["references"], link=o["link"], threshold=o["threshold"],
                        min_points=o["min_points"], min_length=o["min_length"], refine=not o["no_refine"],
                        keep_unrefined=o["keep_unrefined"], keep_cloud_border=o["keep_cloud_border"], join=o["join"],
                        simplify=o["simplify"], seed=o["seed"], progress=ctx.progress)
    meta = {k: v for k, v in res.meta.items() if k != "seconds"}
    meta["input"] = ctx.source
    csv = _csv_path(o)
    written = export_lines(res.lines, geojson=o["output"], dxf=o["dxf"], csv=csv,
                           json=str(Path(csv).with_suffix(".lines.json")) if csv else None,
                           crs=cloud_crs(cloud), meta=meta)
    if o["cloud"]:
        io.write(res.cloud, o["cloud"], progress=ctx.progress)
        written["cloud"] = o["cloud"]
    if o["picture"]:
        from ..render import lines_view

        lines_view(res.cloud, res.lines, o["picture"],
                   title=f"{_name(ctx)}: {len(res.lines)} edge lines, r = {res.meta['radius']:g} m")
        written["picture"] = o["picture"]
    return cloud, {"lines": len(res.lines), "total_length": res.meta["total_length"], "outputs": written,
                   "note": f"{len(res.lines):,} edge lines, {res.meta['total_length']:,.1f} m -> {o['output']}"}


def check_edges(o):
    from ..edges import check_edge_options

    labels = [s.strip() for s in o["labels"].split(",") if s.strip()]
    check_edge_options(o["radius"], labels=labels, min_points=o["min_points"], seed=o["seed"], link=o["link"],
                       threshold=o["threshold"], join=o["join"], simplify=o["simplify"], min_length=o["min_length"])
    _check_csv(o)


def prepare_edges(o, job):
    if not o["use_structure"]:
        from ..structures.references import resolve_references

        resolve_references(o["references"])  # a bad references file is refused before any step runs


def edges_outputs(o):
    out = [(o["output"], "file")]
    csv = _csv_path(o)
    if o["dxf"]:
        out.append((o["dxf"], "file"))
    if csv:
        out += [(csv, "file"), (str(Path(csv).with_suffix(".lines.json")), "file")]
    if o["cloud"]:
        out.append((o["cloud"], "cloud"))
    return out + _picture(o)


def _read_approximations(path: str):
    """2-D approximations of breaklines: the LineStrings of a GeoJSON file, or the polylines of a
    shapefile (pyshp)."""
    if Path(path).suffix.lower() == ".shp":
        try:
            import shapefile
        except ImportError:
            raise LidarfxError("reading a shapefile needs pyshp (pip install pyshp); or give GeoJSON") from None
        try:
            shapes = shapefile.Reader(str(path)).shapes()
        except Exception as exc:  # pyshp raises many kinds
            raise LidarfxError(f"{path}: not a readable shapefile ({exc})") from None
        out = []
        for sh in shapes:
            parts = list(sh.parts) + [len(sh.points)]
            out += [[list(p) for p in sh.points[a:b]] for a, b in zip(parts[:-1], parts[1:]) if b - a >= 2]
        return out
    from ..vector import read_geojson

    lines, _ = read_geojson(Path(path))
    return [ln.vertices for ln in lines]


def run_breaklines(cloud, o, ctx):
    from .._tables import write_csv_rows
    from ..breaklines import extract_breaklines
    from ..crs import cloud_crs
    from ..vector import export_lines

    approx = _read_approximations(o["approximations"]) if o["approximations"] else None
    params = {k: o[k] for k in ("radius", "min_curvature", "patch_length", "patch_width", "gap", "step", "min_angle",
                                "min_points", "max_rms", "min_length", "join", "simplify")}
    classes = None if o["classes"] == "all" else o["classes"]
    res = extract_breaklines(cloud, progress=ctx.progress, classes=classes, approximations=approx, **params)
    info_meta = {k: v for k, v in res.meta.items() if isinstance(v, (int, float, str))}
    csv = _csv_path(o)
    written = export_lines(res.lines, geojson=o["output"], dxf=o["dxf"], csv=csv, crs=cloud_crs(cloud),
                           meta=info_meta)
    if csv:
        vpath = Path(csv).with_suffix(".vertices.csv")
        rows = [{"id": i, "vertex": j, "x": round(float(x), 3), "y": round(float(y), 3), "z": round(float(z), 3),
                 "sigma_xy": ln.attrs["sigma_xy"][j], "sigma_z": ln.attrs["sigma_z"][j], "angle": ln.attrs["angle"][j]}
                for i, ln in enumerate(res.lines) for j, (x, y, z) in enumerate(ln.vertices)]
        write_csv_rows(vpath, rows, ["id", "vertex", "x", "y", "z", "sigma_xy", "sigma_z", "angle"])
        written["vertices_csv"] = str(vpath)
    if o["picture"] and res.ground.any():
        from ..crs import unit_to_metre
        from ..ground.dtm import dtm
        from ..render import breakline_view

        spacing = (1.0 / max(res.meta["density"], 1e-9)) ** 0.5  # m
        cell = float(f"{max(0.5, 2.0 * spacing):.2g}") / unit_to_metre(cloud)
        raster = dtm(cloud.xyz[res.ground], resolution=cell)
        breakline_view(raster, res.lines, o["picture"],
                       title=f"{_name(ctx)}: {len(res.lines)} structure lines, {res.meta['total_length']:,.0f} m")
        written["picture"] = o["picture"]
    return cloud, {"lines": len(res.lines), "total_length": round(res.meta["total_length"], 2), "outputs": written,
                   "note": f"{len(res.lines):,} structure lines, {res.meta['total_length']:,.1f} m -> {o['output']}"}


def check_breaklines(o):
    from ..breaklines import check_breakline_options

    check_breakline_options(**{k: o[k] for k in ("radius", "min_curvature", "patch_length", "patch_width", "gap",
                                                 "step", "min_angle", "min_points", "max_rms", "min_length", "join",
                                                 "simplify")})
    if o["classes"] != "all":
        bad = [c for c in o["classes"] if not 0 <= c <= 255]
        if bad or not o["classes"]:
            raise LidarfxError("classes is a list of class codes 0-255 like [2, 9] (or \"all\")")
    _check_csv(o)


def prepare_breaklines(o, job):
    if o["approximations"]:
        _read_approximations(o["approximations"])


def breaklines_outputs(o):
    out = [(o["output"], "file")]
    csv = _csv_path(o)
    if o["dxf"]:
        out.append((o["dxf"], "file"))
    if csv:
        out += [(csv, "file"), (str(Path(csv).with_suffix(".vertices.csv")), "file")]
    return out + _picture(o)


_POWERLINE_PARAMS = ("radius", "min_height", "linearity", "min_length", "max_gap", "pylon_radius", "tube", "step")


def run_powerlines(cloud, o, ctx):
    from .. import io
    from ..crs import cloud_crs
    from ..powerlines import extract_powerlines
    from ..powerlines.output import load_case_records, write_tables

    cond = ctx.prepared
    params = {k: o[k] for k in _POWERLINE_PARAMS if o[k] is not None}
    res = extract_powerlines(cloud, progress=ctx.progress, **params)
    lc = load_case_records(res, o["load_case"], cond, survey_temperature=o["survey_temp"], step=o["step"]) \
        if o["load_case"] else []
    out = Path(o["outdir"])
    out.mkdir(exist_ok=True)
    written = write_tables(res, out, crs=cloud_crs(cloud), step=o["step"], load_cases=lc,
                           meta={"input": ctx.source, "conductor": cond.name if cond else None,
                                 "survey_temperature": o["survey_temp"] if o["load_case"] else None})
    if o["cloud_format"] != "none":
        path = out / f"cloud.{o['cloud_format']}"
        io.write(res.cloud, path, progress=ctx.progress)
        written["cloud"] = str(path)
    if not o["no_picture"]:
        from ..render import powerline_view

        powerline_view(res, out / "wires.png", title=f"{_name(ctx)}: {len(res.conductors)} conductors, "
                       f"{len(res.spans)} spans, {len(res.pylons)} pylons")
        written["picture"] = str(out / "wires.png")
    return cloud, {"conductors": len(res.conductors), "spans": len(res.spans), "pylons": len(res.pylons),
                   "outputs": written, "note": f"{len(res.conductors)} conductors in {len(res.spans)} spans, "
                   f"{len(res.pylons)} pylons -> {o['outdir']}"}


def check_powerlines(o):
    from ..powerlines.extract import check_powerline_params
    from ..powerlines.loads import parse_load_case

    check_powerline_params({k: o[k] for k in _POWERLINE_PARAMS if o[k] is not None})
    for c in o["load_case"]:
        parse_load_case(c)


def prepare_powerlines(o, job):
    from ..powerlines.loads import conductor

    return conductor(o["conductor"]) if o["load_case"] else None


def run_dtm(cloud, o, ctx):
    from ..ground import classify_ground, dtm

    if o["classify"]:
        mask = classify_ground(cloud, ignore_classes=o["ignore_classes"], progress=ctx.progress, **_smrf(o))
    else:
        if "classification" not in cloud:
            raise LidarfxError("the cloud has no classification; give the dtm step \"classify\": true, or a ground "
                               "step before it")
        mask = cloud["classification"] == 2
    if not mask.any():
        raise LidarfxError("no ground points (class 2); give the dtm step \"classify\": true, or a ground step before it")
    raster = dtm(cloud, o["resolution"], ground=mask)
    raster.write(o["output"])
    return cloud, {"ground_points": int(mask.sum()), "shape": list(raster.shape), "outputs": {"raster": o["output"]},
                   "note": f"DTM {raster.shape[1]}x{raster.shape[0]} cells of {o['resolution']:g} m -> {o['output']}"}


def check_dtm(o):
    from ..ground.dtm import check_resolution

    _check_smrf(o)
    check_resolution(o["resolution"])


def run_render(cloud, o, ctx):
    from ..render.splat import _PICTURE_LIMITS, parse_size, render_picture

    by = o["by"].strip()
    title = o["title"] if o["title"] is not None else f"{_name(ctx)}: {by}"
    _, summary = render_picture(cloud, o["output"], by=by, view=o["view"], size=parse_size(o["size"], _PICTURE_LIMITS),
                                shading=o["shading"], point_size=o["point_size"], cmap=o["cmap"],
                                value_range=o["range"], title=title, progress=ctx.progress)
    return cloud, {"drawn": summary.get("drawn"), "outputs": {"picture": o["output"]},
                   "note": f"{summary.get('drawn', 0):,} points, {o['view']} view by {by} -> {o['output']}"}


def check_render(o):
    from ..colour import check_cmap, check_value_range
    from ..render.splat import _PICTURE_LIMITS, _check_point_size, parse_size

    if not o["by"].strip():
        raise LidarfxError("by needs an attribute name, class, rgb or morphology")
    parse_size(o["size"], _PICTURE_LIMITS)
    _check_point_size(o["point_size"])
    check_value_range(o["range"])
    check_cmap(o["cmap"])


def run_crop(cloud, o, ctx):
    from ..crop import crop_mask

    mask = crop_mask(cloud, bounds=o["bounds"], polygon=ctx.prepared, buffer=o["buffer"], invert=o["invert"])
    kept = int(mask.sum())
    if kept == 0 and not o["allow_empty"]:  # as lidarfx crop: an empty crop is a wrong area
        where = "outside" if o["invert"] else "inside"
        what = f"the polygons of {o['polygon']}" if o["polygon"] else "the box"
        raise LidarfxError(f"no point lies {where} {what}; nothing written (\"allow_empty\": true goes on with "
                           "an empty cloud)")
    out = cloud.subset(mask)
    return out, {"points": kept, "kept": kept, "total": len(cloud),
                 "note": f"kept {kept:,} of {len(cloud):,} points"}


def check_crop(o):
    from ..crop import parse_bounds

    if (o["bounds"] is None) == (o["polygon"] is None):
        raise LidarfxError("give exactly one of bounds and polygon")
    if o["bounds"] is not None:
        parse_bounds(o["bounds"])


def prepare_crop(o, job):
    if o["polygon"]:
        from ..crop import read_area

        return read_area(o["polygon"])  # a bad polygon file is refused before any step runs
    return None


def filter_options(o: dict) -> dict:
    """The options of lidarfx filter, checked as the command checks them."""
    from ..outliers import check_options

    if o["outliers"] == "statistical":
        return check_options("statistical", 8 if o["k"] is None else o["k"], 2.0 if o["std"] is None else o["std"],
                             o["radius"], o["min_neighbours"], o["action"], o["class"])
    if o["k"] is not None or o["std"] is not None:
        raise LidarfxError("k and std belong to outliers statistical; radius takes radius and min_neighbours")
    return check_options("radius", radius=o["radius"], min_neighbours=o["min_neighbours"], action=o["action"],
                         cls=o["class"])


def run_filter(cloud, o, ctx):
    from ..outliers import apply_action, outlier_mask

    f = filter_options(o)
    mask, facts = outlier_mask(cloud, f["method"], k=f.get("k", 8), std=f.get("std", 2.0), radius=f.get("radius"),
                               min_neighbours=f.get("min_neighbours"), progress=ctx.progress)
    out = apply_action(cloud, mask, f["action"], f["class"])
    if f["action"] == "classify":  # a LAS write step afterwards stores the class (lidarfx filter does)
        out.meta["max_class_code"] = max(int(out.meta.get("max_class_code") or 0), f["class"])
    done = f"class {f['class']}" if f["action"] == "classify" else "dropped"
    return out, {"points": len(out), "outliers": facts["outliers"], "action": f["action"],
                 "note": f"{facts['outliers']:,} of {len(cloud):,} points are outliers ({f['method']}): {done}"}


def check_filter(o):
    filter_options(o)


def _scale(o: dict):
    s = o["scale"]
    return None if s is None else s[0] if len(s) == 1 else s


def run_reproject(cloud, o, ctx):
    from ..reproject import reproject

    out = reproject(cloud, o["to"], source=o["from"], scale=_scale(o), ballpark=o["ballpark"], progress=ctx.progress)
    r = out.meta.get("reproject", {})
    return out, {"points": len(out), "from": r.get("from"), "to": r.get("to"),
                 "note": f"{r.get('from')} -> {r.get('to')} ({r.get('operation')})"}


def check_reproject(o):
    from ..reproject import _check_scale, parse_crs

    parse_crs(o["to"], "to")
    if o["from"] is not None:
        parse_crs(o["from"], "from")
    _check_scale(_scale(o))


def _surface_options(o: dict) -> dict:
    from ..surface.models import check_options

    extra = {"freeze_distance": o["freeze_distance"], "thresholds": o["thresholds"]} if "thresholds" in o else {}
    return check_options(resolution=o["resolution"], max_gap=o["max_gap"], exclude_classes=o["exclude_classes"],
                         **extra)


def _raster_info(raster, o: dict, what: str) -> dict:
    rows, cols = raster.shape
    return {"shape": [rows, cols], "outputs": {"raster": o["output"]},
            "note": f"{what} {cols}x{rows} cells of {o['resolution']:g} m -> {o['output']}"}


def run_dsm(cloud, o, ctx):
    from ..surface.models import dsm

    raster = dsm(cloud, o["resolution"], first_returns=o["first_returns"], exclude_classes=o["exclude_classes"],
                 max_gap=o["max_gap"], progress=ctx.progress)
    raster.write(o["output"])
    return cloud, _raster_info(raster, o, "DSM")


def run_chm(cloud, o, ctx):
    from ..surface.models import chm

    raster = chm(cloud, o["resolution"], ground=o["ground"], pit_free=o["pit_free"], thresholds=o["thresholds"],
                 freeze_distance=o["freeze_distance"], max_gap=o["max_gap"], first_returns=not o["all_returns"],
                 exclude_classes=o["exclude_classes"], progress=ctx.progress)
    raster.write(o["output"])
    return cloud, _raster_info(raster, o, "CHM")


def check_surface(o):
    _surface_options(o)


# ============================================================================ the registry
def _cloud_out(name: str, help: str) -> Key:
    return Key(name, "output", None, help)


STEPS: dict[str, Step] = {s.name: s for s in (
    Step("read", "read", "read a point cloud (the first step, and only it)", "lidarfx convert IN OUT",
         "lidarfx.read", (
             Key("path", "input", None, "LAS/LAZ, PLY, text (.xyz/.txt/.csv/.pts) or NumPy (.npy/.npz) file",
                 required=True),
             Key("columns", "text", None, "column spec for text input, e.g. x,y,z,intensity,classification"),
         ), run_read),
    Step("ground", "cloud", "ground classification (SMRF): class 2 ground, 1 other; height above ground, DTM",
         "lidarfx ground", "lidarfx.ground.classify_ground", SMRF + (
             Key("hag", "bool", False, "add the height_above_ground attribute"),
             Key("dtm", "output", None, "also write a DTM raster", suffixes=RASTER),
             Key("resolution", "length", 1.0, "DTM cell"),
         ), run_ground, check_ground,
         outputs=lambda o: _raster_outputs(o["dtm"])),
    Step("features", "cloud", "per-point neighbourhood features", "lidarfx features",
         "lidarfx.compute_features", (
             Key("radius", "lengths", None, "neighbourhood radius; a list for several scales (planarity_r0.50 ...)"),
             Key("features", "texts", None, "groups or names, e.g. \"eigen,plane,density\" or [\"eigen\", \"slope\"] "
                 "(default eigen,plane,density)"),
             Key("neighbourhood", "choice", "sphere", "neighbourhood of the covariance features",
                 choices=("sphere", "cylinder", "knn")),
             Key("k", "int", None, "neighbours for the knn neighbourhood (a radius then caps the search)"),
             Key("scanner", "numbers", None, "scanner position x,y,z: normals towards it (TLS)", count=(3,)),
             Key("height", "length", None, "half-height limit of the vertical cylinder"),
             Key("convention", "choice", "default", "eigenvalue convention",
                 choices=("default", "cloudcompare", "pdal")),
             Key("d_max", "length", 0.10, "plane inlier distance"),
             Key("bins", "int", 10, "bins of the height-difference histogram"),
             Key("seed", "int", 0, "seed of the MSAC generator"),
         ), run_features, check_features, key_aliases={"neighborhood": "neighbourhood"}),
    Step("classify", "cloud", "classify every point with a trained model (lidarfx classify predict)",
         "lidarfx classify predict", "lidarfx.classify.ClassifierModel.classify", (
             Key("model", "text", None, "model file (.skops) or \"default\" (the shipped model)", required=True),
             Key("confidence", "bool", False, "add a float32 confidence attribute"),
             Key("probabilities", "bool", False, "add one float32 probability_NAME attribute per class"),
             Key("precomputed", "bool", False, "read the neighbourhood features from the cloud's attributes"),
             Key("ground", "choice", None, "ground surface of height_above_ground (default: the model's)",
                 choices=("smrf", "class", "attribute")),
             PICTURE,
             Key("min_building_area", "number", None, "object-size rule for buildings, m² (0 = off; default: the model's)"),
             Key("max_multi_return_share", "number", None, "see-through test of that rule (1 = off; default: the model's)"),
         ), run_classify, check_classify, prepare_classify, outputs=_picture, inputs=classify_inputs,
         aliases=("classify_predict",)),
    Step("select", "cloud", "keep the points where an expression holds", "lidarfx select",
         "lidarfx.select.select", (
             Key("where", "text", None, "condition, e.g. \"classification == 2 and z < 300\"", required=True),
             Key("invert", "bool", False, "keep the points where it does not hold"),
         ), run_select, check_select),
    Step("thin", "cloud", "block (voxel) thinning: one point per occupied cubic cell", "lidarfx thin",
         "lidarfx.thin.thin_cloud", (
             Key("cell", "length", None, "cell edge", required=True),
             Key("keep", "choice", "centre", "which point of a cell is kept",
                 choices=("centre", "first", "lowest", "highest", "random")),
             Key("seed", "int", 0, "keep random: the seed"),
         ), run_thin, check_thin),
    Step("colour", "cloud", "RGB from morphology, an attribute, joint sets or classes", "lidarfx colour",
         "lidarfx.colour_cloud", (
             Key("by", "text", "morphology", "morphology, set, class or a numeric attribute"),
             Key("radius", "length", None, "morphology: radius of the normals when the cloud has none"),
             Key("scanner", "numbers", None, "morphology: scanner position x,y,z", count=(3,)),
             Key("sun_azimuth", "number", 315.0, "morphology: sun azimuth, degrees clockwise from North"),
             Key("sun_altitude", "number", 45.0, "morphology: sun altitude, 0-90 degrees"),
             Key("cmap", "text", "viridis", "attribute: matplotlib colour map"),
             Key("range", "numbers", None, "attribute: values at the ends of the colour map (default 2-98 %)",
                 count=(2,)),
             PICTURE,
             Key("view", "choice", "auto", "view of the picture", choices=("auto", "top", "front", "side")),
         ), run_colour, check_colour, outputs=_picture, aliases=("color",)),
    Step("eigenclass", "cloud", "structure classes: plane, border, edge, corner, line, volume ...",
         "lidarfx eigenclass", "lidarfx.classify_structures", (
             Key("radius", "lengths", None, "sphere radius, a list for several scales (default from the spacing)"),
             Key("references", "text", "trained", "trained, analytic or a references file (.json)"),
             Key("weighting", "choice", "structure", "spread per reference and component, or one for all",
                 choices=("structure", "uniform")),
             Key("reject", "number", 3.0, "unclassified beyond this distance in reference standard deviations"),
             Key("min_neighbours", "int", 5, "isolated below this many points in the sphere"),
             Key("keep_signature", "bool", False, "also write e1, e2, e3, centroid_offset, n_neighbours"),
             PICTURE,
         ), run_eigenclass, check_eigenclass, prepare_eigenclass, outputs=_picture, inputs=references_inputs,
         aliases=("structures",)),
    Step("segment", "cloud", "plane segmentation by surface growing: segment_id, segment_size",
         "lidarfx segment", "lidarfx.segment_planes", (
             Key("normal_radius", "length", 0.10, "radius of the local plane fit giving normals"),
             Key("max_distance", "length", 0.10, "largest distance to the segment plane"),
             Key("growing_radius", "length", 0.15, "neighbour radius of the growing"),
             Key("max_angle", "number", 15.0, "largest normal deviation, degrees"),
             Key("min_size", "int", 30, "fewest points per segment"),
             Key("min_width", "length", 0.0, "release segments narrower than this (0 = off)"),
             Key("scanner", "numbers", None, "scanner position x,y,z for the normals (TLS)", count=(3,)),
             Key("keep_features", "bool", False, "also write normal_x/y/z and plane_std"),
             Key("table", "text", None, "per-segment table: writes TABLE.csv and TABLE.json (default: none)"),
             PICTURE,
         ), run_segment, check_segment, outputs=segment_outputs),
    Step("section", "cloud", "the points of a slab around a cut plane, with section_s, section_h, section_d",
         "lidarfx section", "lidarfx.section.section", (
             Key("from", "numbers", None, "start of the section line x,y[,z]", count=(2, 3), required=True),
             Key("to", "numbers", None, "end of the section line x,y[,z]", count=(2, 3), required=True),
             Key("width", "length", None, "slab width across the cut plane, half on each side", required=True),
             Key("normal", "numbers", None, "normal of an inclined cut plane (default: vertical)", count=(3,)),
         ), run_section, check_section),
    Step("crop", "cloud", "keep the points inside a box or polygons (GeoJSON, shapefile), with a buffer",
         "lidarfx crop", "lidarfx.crop.crop", (
             Key("bounds", "numbers", None, "a box xmin,ymin,xmax,ymax[,zmin,zmax] in the cloud's coordinates",
                 count=(4, 6)),
             Key("polygon", "input", None, "polygons: GeoJSON (.geojson, .json) or a shapefile (.shp)"),
             Key("buffer", "length", 0.0, "widen the area by this much (negative: shrink)"),
             Key("invert", "bool", False, "keep the points outside instead"),
             Key("allow_empty", "bool", False, "go on with an empty cloud when no point is kept (else an error)"),
         ), run_crop, check_crop, prepare_crop),
    Step("filter", "cloud", "statistical or radius outliers: classify as noise (class 7) or drop",
         "lidarfx filter", "lidarfx.outliers.filter_outliers", (
             Key("outliers", "choice", None, "the outlier rule", choices=("statistical", "radius"), required=True),
             Key("k", "int", None, "statistical: neighbours (default 8)"),
             Key("std", "number", None, "statistical: standard deviations above the mean (default 2.0)"),
             Key("radius", "length", None, "radius: search radius"),
             Key("min_neighbours", "int", None, "radius: fewest other points within the radius"),
             Key("action", "choice", "classify", "classify the outliers or drop them", choices=("classify", "drop")),
             Key("class", "int", 7, "class of the outliers with action classify (7 low noise, 18 high noise)"),
         ), run_filter, check_filter, key_aliases={"min_neighbors": "min_neighbours"}),
    Step("reproject", "cloud", "coordinates into another CRS with PROJ (no network)", "lidarfx reproject",
         "lidarfx.reproject.reproject", (
             Key("to", "text", None, "target CRS, e.g. EPSG:4326 or EPSG:2154+5720", required=True),
             Key("from", "text", None, "the cloud's CRS when the file has none or a wrong one"),
             Key("scale", "numbers", None, "output coordinate scale: one number or three (x, y, z)", count=(1, 3)),
             Key("ballpark", "bool", False, "accept PROJ's ballpark operation when it knows no other"),
         ), run_reproject, check_reproject),
    Step("edges", "product", "3-D edge lines (ridges, eaves, steps) as GeoJSON, DXF, CSV", "lidarfx edges",
         "lidarfx.extract_edges", (
             Key("output", "output", None, "the lines as GeoJSON", suffixes=LINES, required=True),
             Key("radius", "length", None, "radius of classification and refinement (default from the spacing)"),
             Key("dxf", "output", None, "also write the lines as DXF 3-D polylines", suffixes=(".dxf",)),
             Key("csv", "csv", None, "also write the per-line table (true: OUTPUT with .csv) and .lines.json"),
             PICTURE,
             _cloud_out("cloud", "also write the cloud with structure and edge_candidate"),
             Key("use_structure", "bool", False, "use the cloud's structure attribute (an eigenclass step before)"),
             Key("references", "text", "trained", "references of the classification"),
             Key("labels", "text", "plane_border,edge,corner", "structure labels of the candidate points"),
             Key("min_length", "length", None, "shortest line kept (default: the radius)"),
             Key("min_points", "int", 8, "fewest candidate points of a segment"),
             Key("threshold", "length", None, "RANSAC inlier distance (default 0.5 x radius)"),
             Key("link", "length", None, "link distance of the components (default 0.5 x radius)"),
             Key("join", "length", None, "largest gap between chained segment ends (default: the radius)"),
             Key("simplify", "length", None, "Douglas-Peucker tolerance (default 0.1 x radius)"),
             Key("no_refine", "bool", False, "keep the band lines, do not place them with the cloud"),
             Key("keep_unrefined", "bool", False, "keep segments whose placement failed"),
             Key("keep_cloud_border", "bool", False, "keep lines along the cloud's outer boundary"),
             Key("seed", "int", 0, "seed of the RANSAC draws"),
         ), run_edges, check_edges, prepare_edges, outputs=edges_outputs,
         inputs=references_inputs),
    Step("breaklines", "product", "terrain structure lines (dike crests and toes, ditch edges) in 3-D",
         "lidarfx breaklines", "lidarfx.extract_breaklines", (
             Key("output", "output", None, "the lines as GeoJSON", suffixes=LINES, required=True),
             Key("dxf", "output", None, "also write the lines as DXF 3-D polylines", suffixes=(".dxf",)),
             Key("csv", "csv", None, "also write the per-line table (true: OUTPUT with .csv) and .vertices.csv"),
             PICTURE,
             Key("classes", "codes", [2], "ground classes, e.g. [2, 9]; \"all\" = every point", choices=("all",)),
             Key("approximations", "input", None, "2-D approximations of the lines (GeoJSON or shapefile)"),
             Key("radius", "length", None, "curvature radius (default: about 60 ground points)"),
             Key("min_curvature", "number", None, "start points: |k_max| at least this, 1/m"),
             Key("patch_length", "length", None, "patch length along the line"),
             Key("patch_width", "length", None, "largest patch width each side"),
             Key("gap", "length", None, "gap either side of the line"),
             Key("step", "length", None, "vertex spacing of the growing"),
             Key("min_angle", "number", 8.0, "smallest intersection angle, degrees"),
             Key("min_points", "int", 8, "fewest points per patch"),
             Key("max_rms", "length", None, "largest patch RMS"),
             Key("min_length", "length", 10.0, "shortest line kept"),
             Key("join", "length", None, "largest gap between parts that are connected"),
             Key("simplify", "length", 0.05, "Douglas-Peucker tolerance"),
         ), run_breaklines, check_breaklines, prepare_breaklines, outputs=breaklines_outputs),
    Step("powerlines", "product", "power-line wires: catenaries per conductor and span, pylons, clearances",
         "lidarfx powerlines", "lidarfx.extract_powerlines", (
             Key("outdir", "outdir", None, "output folder (new or empty)", required=True),
             Key("radius", "length", None, "neighbourhood radius of the linearity test (default 1.5)"),
             Key("min_height", "length", None, "lowest wire height above ground (default 4)"),
             Key("linearity", "number", None, "lowest linearity of a wire point (default 0.7)"),
             Key("min_length", "length", None, "shortest wire run (default 30)"),
             Key("max_gap", "length", None, "largest gap along a wire (default 40)"),
             Key("pylon_radius", "length", None, "reach of a pylon around a wire end (default 10)"),
             Key("tube", "length", None, "radius of a wire's tube of points (default 0.5)"),
             Key("step", "length", 0.5, "vertex spacing of the exported curves"),
             Key("load_case", "texts", [], "load cases, e.g. [\"temp=80\", \"ice=10,temp=-5\"]"),
             Key("conductor", "text", "264-AL1/34-ST1A", "conductor type of the load cases"),
             Key("survey_temp", "number", 10.0, "conductor temperature at the survey, °C"),
             Key("cloud_format", "choice", "laz", "format of the classified cloud", choices=("laz", "las", "none")),
             Key("no_picture", "bool", False, "do not draw wires.png"),
         ), run_powerlines, check_powerlines, prepare_powerlines,
         outputs=lambda o: [(o["outdir"], "folder")]),
    Step("dtm", "product", "DTM raster (GeoTIFF / ESRI ASCII) from the ground points", "lidarfx dtm",
         "lidarfx.ground.dtm", (
             Key("output", "output", None, "raster (.tif, .tiff or .asc)", suffixes=RASTER, required=True),
             Key("resolution", "length", 1.0, "cell"),
             Key("classify", "bool", False, "run the ground filter first (else class 2 is ground)"),
         ) + SMRF, run_dtm, check_dtm, outputs=lambda o: _raster_outputs(o["output"])),
    Step("dsm", "product", "DSM raster (GeoTIFF / ESRI ASCII): the highest return per cell", "lidarfx dsm",
         "lidarfx.surface.models.dsm", (
             Key("output", "output", None, "raster (.tif, .tiff or .asc)", suffixes=RASTER, required=True),
             Key("resolution", "length", 1.0, "cell"),
             Key("max_gap", "length", None, "fill empty cells in gaps up to this wide (default 5; 0 = none, "
                 "\"inf\" = all)", choices=("inf",)),
             Key("exclude_classes", "codes", [7, 18], "classes left out (\"none\" for none)"),
             Key("first_returns", "bool", False, "only first returns"),
         ), run_dsm, check_surface, outputs=lambda o: _raster_outputs(o["output"])),
    Step("chm", "product", "canopy height model raster (pit-free): first returns above the ground", "lidarfx chm",
         "lidarfx.surface.models.chm", (
             Key("output", "output", None, "raster (.tif, .tiff or .asc)", suffixes=RASTER, required=True),
             Key("resolution", "length", 1.0, "cell"),
             Key("max_gap", "length", None, "fill empty cells in gaps up to this wide (default 5; 0 = none, "
                 "\"inf\" = all)", choices=("inf",)),
             Key("exclude_classes", "codes", [7, 18], "classes left out (\"none\" for none)"),
             Key("ground", "choice", "auto", "ground points: class 2, the ground filter, or class 2 when present",
                 choices=("auto", "class", "smrf")),
             Key("pit_free", "bool", True, "combine partial CHMs above height thresholds"),
             Key("thresholds", "lengths", None, "heights of the partial CHMs (default 0, 2, 5, 10, 15, every 5 above)"),
             Key("freeze_distance", "length", None, "widest gap a partial CHM above 0 fills"),
             Key("all_returns", "bool", False, "every return, not only first returns"),
         ), run_chm, check_surface, outputs=lambda o: _raster_outputs(o["output"])),
    Step("render", "product", "a picture of the cloud: z-buffered splats, eye-dome lighting, key, scale bar",
         "lidarfx render", "lidarfx.render.render_picture", (
             Key("output", "output", None, "the picture", suffixes=(".png",), required=True),
             Key("by", "text", "z", "an attribute, class, rgb, morphology or set"),
             Key("view", "choice", "top", "view", choices=("top", "front", "side")),
             Key("size", "size", "1600x1200", "picture size in pixels"),
             Key("shading", "choice", "edl", "shading", choices=("edl", "hillshade", "none")),
             Key("point_size", "number", None, "disc radius of every point in pixels (default from the spacing)"),
             Key("range", "numbers", None, "values at the ends of the colour map", count=(2,)),
             Key("cmap", "text", "viridis", "matplotlib colour map"),
             Key("title", "text", None, "title of the picture"),
         ), run_render, check_render),
    Step("write", "write", "write the cloud (any step may be followed by a write; the cloud goes on)",
         "lidarfx convert IN OUT", "lidarfx.write", (
             Key("path", "output", None, "output file; the extension chooses the format", required=True),
             Key("point_format", "int", None, "LAS/LAZ: point format (default: the input's, or what the "
                 "attributes need)"),
             Key("scale", "number", None, "LAS/LAZ: coordinate scale"),
             Key("ascii", "bool", None, "PLY: text instead of binary"),
             Key("precision", "int", None, "text: decimals"),
             Key("delimiter", "text", None, "text: column delimiter"),
             Key("compressed", "bool", None, "NumPy .npz: compressed"),
         ), run_write, write_options),
)}
"""Every step a pipeline may hold, by type name."""

ALIASES = {a: s.name for s in STEPS.values() for a in s.aliases}
"""Other names of steps (``structures`` for ``eigenclass``, ``color`` for ``colour`` ...)."""


def step_of(name: str) -> Step | None:
    """The step called ``name`` (or one of its aliases); None when there is none."""
    if not isinstance(name, str):
        return None
    name = name.replace("-", "_")
    return STEPS.get(ALIASES.get(name, name))

