"""A pipeline in chunks on Dask (``lidarfx run --chunk-size``, :meth:`lidarfx.Pipeline.run_chunked`).

The cloud steps between the read and the one write are fused into one task per chunk
(:mod:`lidarfx.tiles.proc_pipeline`): each chunk reads its square with the sum of the steps'
buffers around it and runs the steps one after the other in memory; the chunks' points are then
merged into the output.  What a chunk cannot know is refused before any work, with the step
named (docs/pipelines.md "In chunks"):

- product steps, ``thin``, ``segment`` and ``section`` work on the whole cloud;
- pictures (``picture`` keys) draw the whole cloud; a ``ground`` step's ``dtm`` too;
- ``classify``, the ``statistical`` filter and ``colour`` by an attribute without ``range``
  take figures of the whole cloud (its usable points and their density; the mean neighbour
  distance; the 2-98 % range), which are computed from the input before the chunks: a step that
  drops or moves points (``crop``, ``select``, ``filter`` with ``action`` drop, ``reproject``)
  may not come before them;
- ``reproject`` is the last cloud step (the chunks' squares are in the input's coordinates).
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable

from ..errors import LidarfxError

CHUNK_STEPS = ("ground", "features", "classify", "select", "colour", "eigenclass", "crop", "filter", "reproject")
"""The cloud steps that run in chunks."""
WHOLE_CLOUD = {
    "thin": "keeps one point per cell of a grid anchored at the whole cloud's minimum",
    "segment": "grows planes over the whole cloud",
    "section": "cuts the whole cloud",
}


def _drops(name: str, o: dict) -> bool:
    return name in ("crop", "select") or (name == "filter" and o["action"] == "drop")


def check_chunkable(pipe) -> None:
    """A one-line error naming the first step a chunked run cannot do as the in-memory run does."""
    steps = pipe.steps
    if steps[0][0].kind != "read":
        raise LidarfxError("a chunked pipeline starts with a read step")
    writes = [i for i, (s, _) in enumerate(steps, 1) if s.kind == "write"]
    if writes != [len(steps)]:
        raise LidarfxError("in chunks, a pipeline has one write step, the last (the chunks are merged into it); "
                           "run without --chunk-size for several writes")
    moved = dropped = None
    earlier: list[tuple[int, str, dict]] = []
    for i, (s, o) in enumerate(steps[1:-1], 2):
        where = f"step {i} ({s.name})"
        if s.kind == "product":
            raise LidarfxError(f"{where} writes a product of the whole cloud and does not run in chunks; run "
                               f"lidarfx {s.name} on the pipeline's output, or run the pipeline in memory "
                               "(--chunk-size 0)")
        if s.name in WHOLE_CLOUD:
            raise LidarfxError(f"{where} {WHOLE_CLOUD[s.name]} and does not run in chunks; run it on the "
                               "pipeline's output, or in memory (--chunk-size 0)")
        if s.name not in CHUNK_STEPS:  # pragma: no cover - every step is one of the above
            raise LidarfxError(f"{where} does not run in chunks")
        if o.get("picture"):
            raise LidarfxError(f"{where}: the picture draws the whole cloud; leave \"picture\" out in chunks")
        if s.name == "ground" and o["dtm"]:
            raise LidarfxError(f"{where}: the DTM is made from the whole cloud; leave \"dtm\" out in chunks and "
                               "run lidarfx dtm on the output")
        if moved is not None:
            raise LidarfxError(f"{where} comes after step {moved} (reproject): in chunks, reproject is the last "
                               "step before the write")
        whole = s.name == "classify" or (s.name == "filter" and o["outliers"] == "statistical") or \
            (s.name == "colour" and o["by"].strip() not in ("morphology", "set", "class") and o["range"] is None)
        if whole and dropped is not None:
            what = {"classify": "the usable points and their density",
                    "filter": "the mean neighbour distance of all points",
                    "colour": "the 2-98 % range of the attribute"}[s.name]
            raise LidarfxError(f"{where} takes {what} from the input, but step {dropped} drops points before it: "
                               f"in chunks, put it before step {dropped}"
                               + (" or give \"range\"" if s.name == "colour" else ""))
        if s.name == "colour" and o["range"] is None and o["by"].strip() not in ("morphology", "set", "class"):
            by = o["by"].strip()
            writer = next((j for j, name, eo in earlier if _writes(name, eo, by)), None)
            if writer is not None:
                raise LidarfxError(f"{where} takes the 2-98 % range of {by} from the input, but step {writer} writes "
                                   f"{by} before it: in chunks, give \"range\": [low, high]")
        if s.name == "colour" and o["by"].strip() == "morphology":
            writer = next((j for j, name, eo in earlier if name == "features" and _computes_normals(eo)), None)
            if writer is not None:
                raise LidarfxError(f"{where} by morphology after step {writer} (features), which computes normals: in "
                                   "chunks, put colour before that step")
        if s.name == "reproject":
            moved = i
        if _drops(s.name, o) and dropped is None:
            dropped = i
        earlier.append((i, s.name, o))
    write_opts = [k for k in ("point_format", "scale", "ascii", "precision", "delimiter", "compressed")
                  if steps[-1][1].get(k) is not None]
    if write_opts:
        raise LidarfxError(f"step {len(steps)} (write): {write_opts[0]} is not applied in chunks (the output keeps the "
                           "input's point format and scales)")
    out = steps[-1][1]["path"]
    if Path(out).suffix.lower() not in (".las", ".laz", ""):
        raise LidarfxError(f"step {len(steps)} (write): in chunks the output is a .las / .laz file or a folder "
                           f"(one file per input tile), not {out}")


def _writes(name: str, o: dict, attribute: str) -> bool:
    """Whether step ``name`` with options ``o`` writes ``attribute``."""
    if name == "ground":
        return attribute in ("classification", "height_above_ground")
    if name == "classify":
        return attribute in ("classification", "confidence") or attribute.startswith("probability_")
    if name == "filter":
        return attribute == "classification" and o["action"] == "classify"
    if name == "eigenclass":
        return attribute in ("structure", "e1", "e2", "e3", "centroid_offset", "n_neighbours")
    if name == "colour":
        return attribute in ("red", "green", "blue")
    if name == "features":
        from ..features.registry import resolve

        from .steps import _feature_list

        names = set(resolve(_feature_list(o)).names)  # several radii: planarity_r0.50 ...
        return attribute in names or attribute.rsplit("_r", 1)[0] in names
    return False


def _colour_options(o: dict, inputs, earlier: list[str]) -> dict:
    from ..tiles.proc_colour import colour_options

    by = o["by"].strip()
    if earlier and by not in ("morphology", "set", "class") and o["range"] is not None:
        from ..colour import check_cmap

        # the attribute may come from an earlier step: the input is not looked at, the range is given
        return {"by": by, "cmap": check_cmap(o["cmap"]).name, "range": [float(v) for v in o["range"]],
                "range_source": "given"}
    return colour_options(inputs, by, radius=o["radius"], scanner=o["scanner"], sun_azimuth=o["sun_azimuth"],
                          sun_altitude=o["sun_altitude"], cmap=o["cmap"], value_range=o["range"], progress=False)


def _computes_normals(o: dict) -> bool:
    from ..colour import NORMAL_NAMES
    from ..features.registry import resolve

    from .steps import _feature_list

    return bool(set(NORMAL_NAMES) & set(resolve(_feature_list(o)).names))


def chunk_options(pipe, inputs) -> list[tuple[int, str, dict]]:
    """``(step, command, options)`` of every cloud step, as the commands' chunked runs take them
    (the whole input's figures computed here, from ``inputs``)."""
    from ..tiles.proc_classes import classify_options, eigenclass_options
    from ..tiles.proc_ground import ground_options
    from ..tiles.proc_ops import crop_options, filter_options as tile_filter_options, reproject_options

    from .steps import _feature_list, _scale, _smrf, filter_options

    out: list[tuple[int, str, dict]] = []
    earlier: list[str] = []
    for i, (s, o) in enumerate(pipe.steps[1:-1], 2):
        try:
            if s.name == "ground":
                opts = ground_options(_smrf(o), ignore_classes=o["ignore_classes"], hag=o["hag"])
            elif s.name == "features":
                opts = {"features": _feature_list(o), "radii": o["radius"] or [], "neighbourhood": o["neighbourhood"],
                        "k": o["k"], "scanner": o["scanner"], "height": o["height"], "convention": o["convention"],
                        "d_max": o["d_max"], "hist_bins": o["bins"], "seed": o["seed"]}
            elif s.name == "classify":
                from ..classify.model import model_path

                opts = classify_options(str(model_path(o["model"])), inputs, ground=o["ground"],
                                        precomputed=o["precomputed"], confidence=o["confidence"],
                                        probabilities=o["probabilities"], min_building_area=o["min_building_area"],
                                        max_multi_return_share=o["max_multi_return_share"])
            elif s.name == "select":
                opts = {"where": o["where"], "invert": bool(o["invert"])}
            elif s.name == "colour":
                opts = _colour_options(o, inputs, earlier)
            elif s.name == "eigenclass":
                opts = eigenclass_options(o["radius"], o["references"], o["weighting"], o["reject"], o["min_neighbours"],
                                          o["keep_signature"], inputs=inputs)
            elif s.name == "crop":
                opts = crop_options(inputs, bounds=o["bounds"], polygon=o["polygon"], buffer=o["buffer"],
                                    invert=o["invert"])
            elif s.name == "filter":
                f = filter_options(o)
                opts = tile_filter_options(f["method"], k=f.get("k", 8), std=f.get("std", 2.0), radius=f.get("radius"),
                                           min_neighbours=f.get("min_neighbours"), action=f["action"], cls=f["class"])
            else:  # reproject
                opts = reproject_options(inputs, o["to"], source=o["from"], scale=_scale(o), ballpark=o["ballpark"])
        except LidarfxError as exc:
            raise LidarfxError(f"step {i} ({s.name}): in chunks: {exc}") from None
        out.append((i, s.name, opts))
        earlier.append(s.name)
    return out


def run_chunked(pipe, *, chunk_size: float | None = None, buffer: float | None = None, workers: int | None = None,
                scheduler: str | None = None, resume: bool = False, work_dir: str | os.PathLike | None = None,
                progress: bool | None = None, log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run ``pipe`` chunk by chunk (:func:`lidarfx.tiles.run_tiled` with the fused steps) and
    return its summary.  Lengths are metres.  See the module docstring for what is refused."""
    from ..crs import inputs_unit_to_metre, length_to_units
    from ..tiles import open_catalog, run_tiled
    from ..tiles.catalog import inputs_of
    from ..tiles.processors import get

    t_all = time.perf_counter()
    check_chunkable(pipe)
    source = pipe.steps[0][1]["path"]
    output = pipe.steps[-1][1]["path"]
    inputs = inputs_of(source)
    steps = chunk_options(pipe, inputs)
    cat = open_catalog(inputs)
    unit = inputs_unit_to_metre(inputs)
    fused, exact_need, extra = [], 0.0, {}
    kw = dict(chunk_size=chunk_size, buffer=buffer, workers=workers, scheduler=scheduler, progress=progress)
    for i, name, opts in steps:
        proc = get(name)
        if proc.metres and "unit_to_metre" not in opts:
            opts = {**opts, "unit_to_metre": unit}
        if name == "filter" and opts["method"] == "statistical":
            from ..tiles.proc_ops import statistical_threshold

            skw = dict(kw)
            opts, facts = statistical_threshold(inputs, output, opts, work_dir=work_dir, kw=skw)
            extra[f"step {i} (filter)"] = facts
        try:
            proc.check(opts)
            reach, exact = proc.buffer(opts, cat.density)
        except LidarfxError as exc:
            raise LidarfxError(f"step {i} ({name}): in chunks: {exc}") from None
        if name == "filter" and opts["method"] == "statistical":
            # every point's k-th neighbour lies within the farthest one found: an exact reach for the
            # points around the square the later steps need, not only for the square's own
            reach, exact = extra[f"step {i} (filter)"]["neighbour_reach_m"] / unit * (1 + 1e-9), True
        fused.append({"step": i, "command": name, "options": opts, "reach": float(reach), "exact": bool(exact)})
        if exact:
            exact_need += float(reach)
    b_units = length_to_units(unit, buffer)
    if b_units is not None and b_units < exact_need * (1 - 1e-12):
        raise LidarfxError(f"--buffer {buffer:g} m is narrower than the {exact_need * unit:g} m the exact steps' "
                           "neighbourhoods reach together; results near chunk borders would differ")
    if log is not None:
        total = sum(f["reach"] for f in fused) * unit
        log(f"{len(fused)} steps fused per chunk: " + ", ".join(f"{f['command']}" for f in fused)
            + f" (buffer {total:.3g} m)")
    res = run_tiled(inputs, output, "pipeline", {"steps": fused}, resume=resume, work_dir=work_dir, **kw)
    outputs = _empty_outputs(pipe, inputs, output, list(res.outputs))
    rows = []
    for f in fused:
        k = [info["steps"][fused.index(f)] for info in res.chunk_infos if "steps" in info]
        row: dict[str, Any] = {"step": f["step"], "type": f["command"], "points": sum(r["points"] for r in k),
                               "buffer_m": float(f"{f['reach'] * unit:.6g}")}
        if f["command"] == "ground":
            row["ground_points"] = sum(r.get("ground_points", 0) for r in k)
        if f["command"] == "classify":
            classes: dict[str, int] = {}
            for r in k:
                for c, n in r.get("classes", {}).items():
                    classes[c] = classes.get(c, 0) + n
            row["classes"] = {int(c): n for c, n in sorted(classes.items(), key=lambda t: int(t[0]))}
        if f"step {f['step']} (filter)" in extra:
            row.update(extra[f"step {f['step']} (filter)"])
        rows.append(row)
    chunks = res.as_dict()
    chunks["seconds"] = {**chunks["seconds"], "total": round(time.perf_counter() - t_all, 3)}
    return {"pipeline": pipe.name, "source": source, "points": rows[-1]["points"] if rows else res.points,
            "points_read": res.points, "steps": rows, "outputs": outputs,
            "chunks": {k: v for k, v in chunks.items() if k not in ("outputs", "points")},
            "seconds": chunks["seconds"]["total"]}


def _empty_outputs(pipe, inputs, output, outputs: list[str]) -> list[str]:
    """The outputs when no point (of a tile) is left: empty files with the input's header, or the
    error of a crop step that does not allow an empty result."""
    from ..io.las import read_header
    from ..tiles.catalog import expand_inputs
    from ..tiles.proc_ops import write_empty

    out = Path(output)
    sources = expand_inputs(inputs)
    if out.suffix.lower() in (".las", ".laz"):
        missing = [(out, sources[0])] if not outputs else []
    else:
        done = {Path(p).name for p in outputs}
        missing = [(out / s.name, s) for s in sources if s.name not in done]
    if missing and not outputs:
        for i, (s, o) in enumerate(pipe.steps, 1):
            if s.name == "crop" and not o["allow_empty"]:
                raise LidarfxError(f"step {i} (crop): no point is left; nothing written (\"allow_empty\": true "
                                   "writes an empty file)")
    if missing and not out.suffix:
        out.mkdir(exist_ok=True)
    for path, src in missing:
        write_empty(path, read_header(src))
    return outputs + [str(p) for p, _ in missing]


__all__ = ["CHUNK_STEPS", "check_chunkable", "chunk_options", "run_chunked"]
