"""Classification reports as text, JSON and a folder of files (pictures: :mod:`lidarfx.render.classify_plots`)."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

from ..errors import LidarfxError
from ..render.classify_plots import plot_confusion, plot_elimination, plot_importance
from .metrics import LAYOUT

__all__ = ["format_value", "format_metrics", "format_slope_table", "format_report", "small_buildings_line",
           "not_trained_note", "interval_line", "report_json", "write_report", "report_dir", "file_stem"]


def format_value(v: float | None, nd: int = 4) -> str:
    """A figure with ``nd`` decimals; NaN and None (``null`` in JSON) as ``   nan``."""
    return "   nan" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}"


_f = format_value


def interval_line(ci: dict[str, Any]) -> str:
    """The line of a metrics dict's ``ci`` (:func:`~lidarfx.classify.metrics.block_bootstrap`)."""
    size = f" of {ci['block_size']:g} m" if ci.get("block_size") else ""
    within = f", drawn within each of the {ci['strata']} files" if ci.get("strata") else ""
    return (f"{ci['level']:.0%} interval (bootstrap of {ci['blocks']} blocks{size}{within}): "
            f"OA {_f(ci['oa'][0])}–{_f(ci['oa'][1])}   kappa {_f(ci['kappa'][0])}–{_f(ci['kappa'][1])}   "
            f"mean F1 {_f(ci['mean_f1'][0])}–{_f(ci['mean_f1'][1])}")


def format_metrics(m: dict[str, Any], title: str | None = None) -> str:
    """Text table of one metrics dict (per-class rows, then the confusion matrix)."""
    lines = []
    if title:
        lines.append(title)
    lines.append(f"points {m['points']:,}   OA {_f(m['oa'])}   kappa {_f(m['kappa'])}   "
                 f"mean F1 {_f(m['mean_f1'])}   mean IoU {_f(m['mean_iou'])}")
    if m.get("ci"):
        lines.append(interval_line(m["ci"]))
        lines += [f"  note on the interval: {note}" for note in m.get("interval_notes", [])]
    w = max([len(c["name"]) for c in m["classes"]] + [5])
    lines.append(f"  {'class':<{w}} {'codes':>8} {'support':>9} {'PA':>7} {'UA':>7} {'F1':>7} {'IoU':>7}")
    for c in m["classes"]:
        lines.append(f"  {c['name']:<{w}} {str(c['code']):>8} {c['support']:>9,} {_f(c['pa']):>7} "
                     f"{_f(c['ua']):>7} {_f(c['f1']):>7} {_f(c['iou']):>7}"
                     + ("  (no reference points: not in the means)" if c["support"] == 0 else ""))
    lines.append(f"  confusion matrix ({LAYOUT}):")
    cw = max(9, max(len(f"{v:,}") for row in m["confusion"] for v in row) + 1)
    lines.append("  " + " " * w + "".join(f"{c['name'][:cw - 1]:>{cw}}" for c in m["classes"]))
    for c, row in zip(m["classes"], m["confusion"]):
        lines.append(f"  {c['name']:<{w}}" + "".join(f"{v:>{cw},}" for v in row))
    return "\n".join(lines)


def format_slope_table(rows: list[dict[str, Any]]) -> str:
    """Text table of a ``by_slope`` breakdown: points, OA and PA per class per slope class."""
    names = list(rows[0]["pa"]) if rows else []
    w = max([len(n) for n in names] + [7])
    out = ["  by terrain slope (1 m DTM of the SMRF ground):",
           f"  {'slope':>9} {'points':>9} {'OA':>7}" + "".join(f" {'PA ' + n:>{w + 3}}" for n in names)]
    for r in rows:
        lo, hi = r["slope_deg"]
        out.append(f"  {f'{lo:g}–{hi:g}°':>9} {r['points']:>9,} {_f(r['oa']):>7}"
                   + "".join(f" {_f(r['pa'][n]):>{w + 3}}" for n in names))
    return "\n".join(out)


def small_buildings_line(sb: dict[str, Any]) -> str:
    """One line on the small-building rule's counts (``small_buildings`` of a section or file)."""
    text = (f"small-building rule ({sb['min_building_area']:g} m², docs/classification.md §2): "
            f"{sb.get('relabelled_components', 0):,} of {sb.get('components', 0):,} predicted-building clusters "
            f"relabelled ({sb.get('relabelled_points', 0):,} points), {sb.get('kept_at_edge', 0):,} small ones "
            "kept at the data's edge")
    share = sb.get("max_multi_return_share", 1.0)
    if share < 1:
        text += (f"; see-through test (> {share:g} of the points from multi-return pulses): "
                 f"{sb.get('see_through_components', 0):,} clusters relabelled "
                 f"({sb.get('see_through_points', 0):,} points)")
        if sb.get("see_through_untested"):
            text += ", not run where the data record no return numbers"
    return text


def not_trained_note(fold: dict[str, Any]) -> str:
    """The note on a fold whose training part lacks classes (empty if none)."""
    absent = fold.get("not_trained")
    if not absent:
        return ""
    return (f"; its training part has no {', '.join(repr(str(a)) for a in absent)} points, so none of its "
            f"held-out points can be called {'that' if len(absent) == 1 else 'those'}")


def format_report(report: dict[str, Any]) -> str:
    """The whole report as text: one block per section, then importances."""
    out = [f"lidarfx {report.get('lidarfx_version', '')} classification report",
           f"classes: {report.get('class_spec', '')}",
           f"classifier: {report['config']['classifier']}, {len(report['features'])} features, "
           f"radii {', '.join(f'{r:g}' for r in report['config']['radii'])} m, "
           f"max {report['config']['max_per_class']} training points per class",
           f"training files: {', '.join(Path(f['name']).name for f in report['train_files'])}", ""]
    for key, sec in report["sections"].items():
        out.append(f"== {sec['title']} [{key}] ==")
        if "block_size" in sec:
            out.append(f"{sec['blocks']} blocks of {sec['block_size']:g} m")
        if sec.get("buffer"):
            out.append(f"training points within {sec['buffer']:g} m of the held-out "
                       f"{'blocks' if 'block_size' in sec else 'file'} are left out of that fold's training")
        for pf in sec.get("folds", []):
            label = Path(pf["file"]).name if "file" in pf else f"fold {pf['fold']}"
            left = f", {pf['buffer_excluded']:,} training points in the buffer" if pf.get("buffer_excluded") else ""
            out.append(f"  {label}: test {pf['test_points']:,} points, OA {_f(pf['oa'])}, "
                       f"mean F1 {_f(pf['mean_f1'])}{left}{not_trained_note(pf)}")
        if sec.get("small_buildings"):
            out.append(small_buildings_line(sec["small_buildings"]))
        if key == "test":
            for name, m in sec["files"].items():
                d = m.get("density")
                dens = (f" ({d['density']:.1f} pts/m², {d['ratio']:.2f} × the training density)" if d else "")
                out.append(format_metrics(m, f"-- {Path(name).name}{dens}"))
                if m.get("small_buildings"):
                    out.append(small_buildings_line(m["small_buildings"]))
                if m.get("by_slope"):
                    out.append(format_slope_table(m["by_slope"]))
            out.append(format_metrics(sec["metrics"], "-- all test files pooled"))
            if sec["metrics"].get("by_slope") and len(sec["files"]) > 1:
                out.append(format_slope_table(sec["metrics"]["by_slope"]))
        else:
            out.append(format_metrics(sec["metrics"]))
        out.append("")
    imp = report.get("importance")
    if imp:
        out.append("== feature importance (top 15) ==")
        out.append(f"impurity ({imp.get('impurity_model')}):")
        for r in imp["impurity"][:15]:
            out.append(f"  {r['name']:<32} {r['importance']:.4f}")
        if "permutation" in imp:
            out.append(f"permutation, drop of mean F1 ({imp.get('permutation_data')}):")
            for r in imp["permutation"][:15]:
                out.append(f"  {r['name']:<32} {r['mean']:.4f} ± {r['std']:.4f}")
        out.append("")
    be = report.get("backward_elimination")
    if be:
        out.append("== backward elimination (Chehata 2009; random forest) ==")
        for st in be["steps"]:
            out.append(f"  {st['n_features']:3d} features: OA {_f(st['oa'])}, mean F1 {_f(st['mean_f1'])}")
        b = be["best"]
        out.append(f"smallest set within {be['tolerance']} of the best mean F1: {b['n_features']} features: "
                   + ", ".join(b["features"]))
        out.append("")
    if report.get("seconds"):
        out.append("seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in report["seconds"].items()))
    return "\n".join(out)


def report_json(report: dict[str, Any]) -> str:
    """The report as strict JSON (NaN → null)."""
    from .._json import dumps

    return dumps(report, indent=2)


def report_dir(path: str | os.PathLike, create: bool = True) -> Path:
    """The report folder (an error if it is a file), created if missing and ``create``."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise LidarfxError(f"{d} exists and is not a folder")
    if create:
        d.mkdir(parents=True, exist_ok=True)
    return d


def file_stem(name: str) -> str:
    """A file name's stem for the names of its pictures (spaces → ``_``)."""
    return Path(name).stem.replace(" ", "_")


def write_report(report: dict[str, Any], out_dir: str | os.PathLike) -> list[Path]:
    """``report.txt``, ``report.json`` and ``confusion_<section>.png`` (pooled, and one
    per test file) in ``out_dir`` (created if missing; each file written atomically)."""
    from .._atomic import atomic_path

    d = report_dir(out_dir)
    written = []
    with atomic_path(d / "report.txt") as tmp:
        tmp.write_text(format_report(report) + "\n")
    written.append(d / "report.txt")
    with atomic_path(d / "report.json") as tmp:
        tmp.write_text(report_json(report) + "\n")
    written.append(d / "report.json")
    for key, sec in report["sections"].items():
        written.append(plot_confusion(sec["metrics"], d / f"confusion_{key}.png", title=sec["title"]))
        if key == "test" and len(sec["files"]) > 1:
            for name, m in sec["files"].items():
                written.append(plot_confusion(m, d / f"confusion_test_{file_stem(name)}.png",
                                              title=f"test: {Path(name).name}"))
        if key == "test":
            written += [Path(m["error_map"]) for m in sec["files"].values() if m.get("error_map")]
    if report.get("importance"):
        written.append(plot_importance(report["importance"], d / "importance.png"))
    if report.get("backward_elimination"):
        written.append(plot_elimination(report["backward_elimination"], d / "backward_elimination.png"))
    return written
