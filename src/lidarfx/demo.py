"""The demo: the main job of lidarfx on synthetic scenes with ground truth.

Five scenes of :mod:`lidarfx.synth`, each run through its product and scored against the
scene's truth:

``facade``     features at three radii, a classifier trained on one facade scan and
               applied to another (overall accuracy, mean F1, per-class F1);
``rockface``   discontinuities: joint sets found without being told how many (angle of each
               set mean to the true set, share of the points given the right set);
``powerline``  wires, catenaries, pylons (conductors found, wire points' completeness and
               correctness, sag and catenary-parameter errors);
``house``      3-D edge lines (share of each true ridge / eave / verge line covered);
``dike``       breaklines of a dike and a ditch (completeness, plan and height RMS).

:func:`run_demo` writes one folder per scene (the scene as LAZ, the products, pictures and
an HTML report) and an ``index.html`` linking them, with every figure beside its target.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .cloud import PointCloud

SCENES = ("facade", "rockface", "powerline", "house", "dike")
"""The demo's scenes, in the order they run."""


@dataclass
class DemoScene:
    """One scene of the demo: its cloud with the products' attributes, the figures against the
    truth (``{"measure", "value", "target", "pass"}`` rows), the product lines, the pictures
    and tables, the files written (name → path) and the seconds taken."""

    name: str
    title: str
    cloud: PointCloud
    figures: list[dict[str, Any]]
    lines: dict[str, list] = field(default_factory=dict)
    pictures: list[tuple[str, str]] = field(default_factory=list)
    tables: list[tuple[str, list[dict[str, Any]]]] = field(default_factory=list)
    files: dict[str, str] = field(default_factory=dict)
    colour_by: str | None = None
    labels: dict[str, dict[int, str]] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        return all(f["pass"] is not False for f in self.figures)


def _figure(measure: str, value: float, target: str, ok: bool | None) -> dict[str, Any]:
    v = float(value)
    return {"measure": measure, "value": round(v, 4) if math.isfinite(v) else None, "target": target,
            "pass": None if ok is None else bool(ok)}


# ----------------------------------------------------------------------------- the scenes
def facade_scene(out: Path, seed: int = 1) -> DemoScene:
    """Features and supervised classification: train on facade ``seed``, classify facade
    ``seed + 1`` (another random scan of the same kind of scene), score against its truth."""
    from . import io, synth
    from .classify import confusion_matrix, metrics, plot_confusion, train
    from .features import compute_features

    train_scene = synth.facade(seed=seed)
    test_scene = synth.facade(seed=seed + 1)
    radii = [0.1, 0.3, 0.5]
    model = train([train_scene], radii=radii, features=["eigen", "plane", "density", "height"], classifier="hgb",
                  max_per_class=5000, seed=seed)
    truth = np.asarray(test_scene["classification"]).copy()
    got = model.classify(test_scene)
    pred = np.asarray(got["classification"])
    names = list(model.classes.names)
    ref_idx = model.classes.index_of(truth)
    pred_idx = model.classes.index_of(pred)
    keep = (ref_idx >= 0) & (pred_idx >= 0)
    m = metrics(confusion_matrix(ref_idx[keep], pred_idx[keep], len(names)), names, list(model.classes.codes))
    cloud = got
    fx = compute_features(test_scene, ["planarity", "linearity", "verticality", "sphericity"], radius=0.3)
    cloud.update({f"{n}_r0.30": np.asarray(fx[n]) for n in ("planarity", "linearity", "verticality", "sphericity")})
    cloud["truth_class"] = truth
    cloud["correct"] = (pred == truth).astype(np.uint8)
    files = {"scene": str(out / "facade_test.laz"), "classified": str(out / "facade_classified.laz")}
    io.write(test_scene, files["scene"])
    io.write(cloud, files["classified"])
    pic = plot_confusion(m, out / "confusion.png", title="facade: classes of an unseen scan")
    files["confusion"] = str(pic)
    figures = [_figure("overall accuracy", m["oa"], "≥ 0.95", m["oa"] >= 0.95),
               _figure("mean F1", m["mean_f1"], "≥ 0.80", m["mean_f1"] >= 0.80)]
    rows = [{k: c[k] for k in ("name", "code", "support", "pa", "ua", "f1", "iou")} for c in m["classes"]]
    code_names = {int(c): n for c, n in zip(model.classes.codes, names)}
    return DemoScene("facade", "Facade: features and classification", cloud, figures,
                     pictures=[(str(pic), "confusion matrix of the unseen scan (rows: truth)")],
                     tables=[("per class (unseen scan)", rows)], files=files, colour_by="classification",
                     labels={"classification": code_names, "truth_class": code_names})


def rockface_scene(out: Path, seed: int = 1) -> DemoScene:
    """Discontinuities of a synthetic rock face: joint sets against the true sets."""
    from . import io, synth
    from .discontinuities import analyse_discontinuities
    from .discontinuities.output import draw_pictures, write_tables
    from .discontinuities.stats import axial_angle
    from .geometry import normal_from_dip

    scene = synth.rockface(seed=seed)
    truth = scene.meta["truth"]
    res = analyse_discontinuities(scene, scanner=truth["scanners"])
    mapping, rows = {}, []
    for s in res.sets:
        ang = [float(axial_angle(normal_from_dip(s["dip"], s["dip_direction"]), t["normal"])) for t in truth["sets"]]
        k = int(np.argmin(ang))
        mapping[s["id"]] = k
        t = truth["sets"][k]
        rows.append({"set": s["id"], "dip": s["dip"], "dip direction": s["dip_direction"], "true set": k,
                     "true dip": t["dip"], "true dip direction": t["dip_direction"], "angle": ang[k],
                     "kappa": s["kappa"], "points": s["points"]})
    js = np.asarray(scene["joint_set"])
    got = np.asarray(res.cloud["set_id"])
    table = np.array([-1] + [mapping.get(k, -1) for k in range(len(res.sets))])
    ok = js >= 0
    accuracy = float((table[got + 1][ok] == js[ok]).mean()) if ok.any() else math.nan
    worst = max((r["angle"] for r in rows), default=math.nan)
    found = sorted(set(mapping.values())) == list(range(len(truth["sets"]))) and len(res.sets) == len(truth["sets"])
    figures = [_figure("sets found (true: %d)" % len(truth["sets"]), len(res.sets), "= true", found),
               _figure("largest angle to the true set, °", worst, "≤ 3°", worst <= 3.0),
               _figure("points given the right set", accuracy, "≥ 0.90", accuracy >= 0.90)]
    files = {"scene": str(out / "rockface.laz"), "cloud": str(out / "rockface_sets.laz")}
    io.write(scene, files["scene"])
    io.write(res.cloud, files["cloud"])
    files.update(write_tables(res, out, meta={"input": "synth.rockface"}))
    pics = draw_pictures(res, out, name="synthetic rock face")
    files.update(pics)
    return DemoScene("rockface", "Rock face: joint sets", res.cloud, figures,
                     pictures=[(p, Path(p).stem) for p in pics.values()], tables=[("joint sets", rows)], files=files,
                     colour_by="set_id")


def powerline_scene(out: Path, seed: int = 0) -> DemoScene:
    """Power lines of a synthetic corridor: conductors, wire points and catenaries against the truth."""
    from . import io, synth
    from .crs import cloud_crs
    from .powerlines import extract_powerlines
    from .powerlines.output import conductor_polylines, write_tables
    from .render import powerline_view

    scene = synth.powerline(seed=seed)
    truth = scene.meta["truth"]
    ref = np.asarray(scene["classification"]).copy()
    hidden = scene.copy()
    cls = ref.copy()
    cls[cls != 2] = 1  # the classes the extraction must find are hidden from it
    hidden["classification"] = cls
    res = extract_powerlines(hidden)
    pred = np.asarray(res.cloud["classification"]) == 14
    tp = int((pred & (ref == 14)).sum())
    completeness = tp / max(int((ref == 14).sum()), 1)
    correctness = tp / max(int(pred.sum()), 1)
    wire_of = np.asarray(scene["wire_id"])
    rows, sag_err, a_err = [], [], []
    for cd in res.conductors:
        w, c = np.unique(wire_of[cd.index], return_counts=True)
        k = int(w[np.argmax(c)])
        t = truth["wires"][k] if 0 <= k < len(truth["wires"]) else None
        row = {"conductor": cd.id, "true wire": k, "points": int(len(cd.index)), "sag": cd.measures["sag"],
               "true sag": t["sag"] if t else None, "a": cd.a, "true a": t["a"] if t else None,
               "rmse": cd.measures["rmse"]}
        rows.append(row)
        if t:
            sag_err.append(abs(cd.measures["sag"] - t["sag"]))
            a_err.append(abs(cd.a / t["a"] - 1.0))
    max_sag = max(sag_err, default=math.nan)
    max_a = max(a_err, default=math.nan)
    figures = [_figure(f"conductors found (true: {len(truth['wires'])})", len(res.conductors), "= true",
                       len(res.conductors) == len(truth["wires"])),
               _figure("wire points: completeness", completeness, "≥ 0.95", completeness >= 0.95),
               _figure("wire points: correctness", correctness, "≥ 0.95", correctness >= 0.95),
               _figure("largest sag error, m", max_sag, "≤ 0.10 m", max_sag <= 0.10),
               _figure("largest catenary-parameter error (share)", max_a, "≤ 0.05", max_a <= 0.05)]
    files = {"scene": str(out / "corridor.laz"), "cloud": str(out / "corridor_wires.laz")}
    io.write(scene, files["scene"])
    io.write(res.cloud, files["cloud"])
    files.update(write_tables(res, out, crs=cloud_crs(scene), meta={"input": "synth.powerline"}))
    pic = powerline_view(res, out / "wires.png", title="synthetic corridor: wires, catenaries, profiles")
    files["picture"] = str(pic)
    return DemoScene("powerline", "Power-line corridor: wires and catenaries", res.cloud, figures,
                     lines={"catenaries": conductor_polylines(res)}, pictures=[(str(pic), "wires and catenaries")],
                     tables=[("conductors against the true wires", rows)], files=files, colour_by="classification")


def _line_scores(found: Sequence, truth_lines: Sequence[np.ndarray], within: float) -> list[float]:
    from .breaklines import line_distances

    return [float(line_distances(found, [t], step=min(0.5, within), within=within)["completeness"])
            for t in truth_lines]


def house_scene(out: Path, seed: int = 0) -> DemoScene:
    """3-D edge lines of a synthetic house against its true ridge, eave and verge lines."""
    from . import io, synth
    from .edges import extract_edges
    from .crs import cloud_crs
    from .render import lines_view
    from .vector import export_lines

    scene = synth.house(seed=seed)
    res = extract_edges(scene)
    truth = scene.meta["truth"]["lines"]
    arrays = [np.array([ln["start"], ln["end"]], dtype=float) for ln in truth]
    cover = _line_scores(res.lines, arrays, within=0.10)
    rows = [{"line": ln["kind"], "side": ln.get("side", ""), "length": float(np.linalg.norm(a[1] - a[0])),
             "covered within 0.10 m": c} for ln, a, c in zip(truth, arrays, cover)]
    ridge = [c for ln, c in zip(truth, cover) if ln["kind"] == "ridge"]
    eaves = [c for ln, c in zip(truth, cover) if ln["kind"] == "eave"]
    figures = [_figure("ridge covered (share of its length)", min(ridge, default=math.nan), "≥ 0.90",
                       min(ridge, default=0.0) >= 0.90),
               _figure("eaves covered (the lesser)", min(eaves, default=math.nan), "≥ 0.90",
                       min(eaves, default=0.0) >= 0.90),
               _figure("mean cover of all true lines", float(np.mean(cover)) if cover else math.nan, "", None)]
    files = {"scene": str(out / "house.laz")}
    io.write(scene, files["scene"])
    files.update(export_lines(res.lines, geojson=out / "edges.geojson", dxf=out / "edges.dxf",
                              crs=cloud_crs(scene), meta={"input": "synth.house"}))
    pic = lines_view(res.cloud, res.lines, out / "edges.png", title="synthetic house: edge lines")
    files["picture"] = str(pic)
    from .structures import LABELS

    return DemoScene("house", "House: 3-D edge lines", res.cloud, figures, lines={"edge lines": res.lines},
                     pictures=[(str(pic), "edge lines over the points")], tables=[("true lines", rows)],
                     files=files, colour_by="structure", labels={"structure": dict(LABELS)})


def dike_scene(out: Path, seed: int = 0) -> DemoScene:
    """Breaklines of a synthetic ALS tile with a dike and a ditch against the true lines."""
    from . import io, synth
    from .breaklines import extract_breaklines, line_distances
    from .crs import cloud_crs
    from .ground.dtm import dtm
    from .render import breakline_view
    from .vector import export_lines

    scene = synth.terrain(seed=seed)
    truth = scene.meta["truth"]["breaklines"]
    res = extract_breaklines(scene)
    rows = []
    kinds: dict[str, list] = {}
    for b in truth:
        kinds.setdefault(b["kind"], []).append(np.asarray(b["points"], dtype=float))
    comp = []
    for kind, refs in kinds.items():
        d = line_distances(res.lines, refs)
        rows.append({"kind": kind, "lines": len(refs), "completeness": d["completeness"], "rms plan": d["rms_xy"],
                     "rms height": d["rms_z"]})
        comp.append(d)
    dike = [r for r in rows if r["kind"].startswith("dike")]
    worst = min((r["completeness"] for r in dike), default=math.nan)
    rms_xy = max((r["rms plan"] for r in dike), default=math.nan)
    rms_z = max((r["rms height"] for r in dike), default=math.nan)
    figures = [_figure("dike lines: completeness (the least)", worst, "≥ 0.90", worst >= 0.90),
               _figure("dike lines: RMS in plan, m", rms_xy, "≤ 0.25 m", rms_xy <= 0.25),
               _figure("dike lines: RMS in height, m", rms_z, "≤ 0.10 m", rms_z <= 0.10)]
    files = {"scene": str(out / "dike.laz")}
    io.write(scene, files["scene"])
    files.update(export_lines(res.lines, geojson=out / "breaklines.geojson", dxf=out / "breaklines.dxf",
                              crs=cloud_crs(scene), meta={"input": "synth.terrain"}))
    raster = dtm(scene.xyz[res.ground], resolution=1.0)
    pic = breakline_view(raster, res.lines, out / "breaklines.png",
                         reference=[np.asarray(b["points"], dtype=float) for b in truth],
                         title="synthetic dike and ditch: breaklines (reference dashed)")
    files["picture"] = str(pic)
    return DemoScene("dike", "Dike and ditch: breaklines", scene, figures, lines={"breaklines": res.lines},
                     pictures=[(str(pic), "breaklines over the shaded DTM")], tables=[("lines by kind", rows)],
                     files=files, colour_by="z")


SCENE_RUNNERS: dict[str, Callable[..., DemoScene]] = {
    "facade": facade_scene, "rockface": rockface_scene, "powerline": powerline_scene, "house": house_scene,
    "dike": dike_scene}


# ----------------------------------------------------------------------------- the whole demo
def scene_report(scene: DemoScene, folder: Path) -> Path:
    """``folder/index.html``: the scene's cloud and products in the viewer, figures, pictures, tables."""
    from .report import Report
    from .report.sections import known_labels, line_layer, product_first

    rep = Report(scene.title, command="lidarfx demo")
    rep.add_summary({"points": len(scene.cloud), "seconds": round(scene.seconds, 2),
                     "all targets met": "yes" if scene.passed else "no"})
    rep.add_table("figures against the scene's truth", scene.figures)
    rep.add_cloud(scene.cloud, product_first(scene.cloud, scene.colour_by),
                  labels={**known_labels(scene.cloud), **scene.labels}, colour_by=scene.colour_by)
    for name, layer in scene.lines.items():
        arrays, props = line_layer(layer)
        if arrays:
            rep.add_lines(name, arrays, properties=props)
    for path, caption in scene.pictures:
        rep.add_picture(path, caption)
    for title, rows in scene.tables:
        rep.add_table(title, rows)
    for name, path in scene.files.items():
        rep.add_link(name, Path(path).name, "")
    return rep.write(folder)


def run_demo(out: str | Path, scenes: Sequence[str] | None = None, *, seed: int | None = None,
             progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the demo's scenes (default: all of :data:`SCENES`) into ``out`` (a folder per scene
    and ``index.html``).  ``seed``: the seed of every scene (default: each scene's own).
    Returns ``{"scenes": [...], "index": path, "seconds": ...}``: per scene its figures, files,
    report and seconds.  ``progress`` gets a line per finished scene."""
    from .errors import LidarfxError
    from .report import Report

    names = list(SCENES if scenes is None else scenes)
    unknown = [n for n in names if n not in SCENE_RUNNERS]
    if unknown:
        raise LidarfxError(f"unknown demo scene {unknown[0]!r}; the scenes are {', '.join(SCENES)}")
    out = Path(out)
    t0 = time.perf_counter()
    done: list[dict[str, Any]] = []
    index = Report("lidarfx demo: the main job on synthetic scenes with ground truth", command="lidarfx demo")
    overview = []
    for name in names:
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        scene = SCENE_RUNNERS[name](folder) if seed is None else SCENE_RUNNERS[name](folder, seed=seed)
        scene.seconds = time.perf_counter() - t
        page = scene_report(scene, folder)
        rec = {"name": name, "title": scene.title, "points": len(scene.cloud), "seconds": round(scene.seconds, 2),
               "passed": scene.passed, "figures": scene.figures, "files": scene.files, "report": str(page)}
        done.append(rec)
        for f in scene.figures:
            overview.append({"scene": name, **f})
        index.add_link(scene.title, f"{name}/index.html",
                       f"{len(scene.cloud):,} points, {scene.seconds:.1f} s, "
                       + ("all targets met" if scene.passed else "a target missed"))
        if progress is not None:
            progress(f"{name}: {len(scene.cloud):,} points, {scene.seconds:.1f} s, "
                     + ("all targets met" if scene.passed else "a target missed"))
    seconds = time.perf_counter() - t0
    index.add_summary({"scenes": len(done), "points": sum(r["points"] for r in done), "seconds": round(seconds, 1),
                       "all targets met": "yes" if all(r["passed"] for r in done) else "no"})
    index.add_table("figures against the scenes' truth", overview)
    page = index.write(out)
    return {"scenes": done, "index": str(page), "seconds": round(seconds, 2)}
