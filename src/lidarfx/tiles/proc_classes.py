"""``lidarfx eigenclass`` and ``lidarfx classify predict`` in chunks (:mod:`lidarfx.tiles`).

Both compute sphere-neighbourhood features of the owned points over the chunk's buffered cloud,
with the neighbour index laid out as the whole cloud's (its origin), so every point's values
equal one in-memory run's bit for bit; the buffer is the largest radius.

What depends on the whole cloud is computed once before the run or asked for:

- ``eigenclass``: the default radius (from the whole cloud's point spacing) — give ``-r``;
- ``classify``: :func:`classify_options` reads the inputs once (twice when the model thins
  dense clouds) for the usable points' minimum (the index origin), their count and density (the
  thinning of the neighbour cloud and the density warning); the height above ground comes from
  the input's ``height_above_ground`` attribute (``--ground attribute``: SMRF and the class-2
  TIN are not local), the small-building rule is off (``--min-building-area 0``: its clusters
  span chunks), and the inputs that use whole-cloud statistics (``intensity_norm``, ``z``,
  ``pulse_*``) and kNN models are refused.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import LidarfxError
from .processors import Processor

# --------------------------------------------------------------------------- eigenclass


def eigenclass_options(radii, references="trained", weighting="structure", reject=None, min_neighbours=None,
                       keep_signature=False, inputs=None) -> dict:
    """The options of a chunked ``eigenclass`` run (plain JSON).  Without ``radii`` a one-line
    error: the default radius comes from the whole cloud's point spacing; the message proposes
    one from the inputs' mean density (``inputs``: a file, files or a folder)."""
    from ..features.api import radii_list
    from ..structures import DEFAULT_MIN_NEIGHBOURS, DEFAULT_REJECT

    rs = radii_list(None, radii or [])
    if not rs:
        hint = ""
        if inputs is not None:
            try:
                from .catalog import open_catalog

                from ..crs import inputs_unit_to_metre

                cat = open_catalog(inputs)
                u = inputs_unit_to_metre(inputs)
                rho = cat.density / (u * u)  # points per m²
                hint = (f"; at the inputs' mean density ({rho:.3g} points per m²) about "
                        f"-r {float(f'{math.sqrt(40.0 / (math.pi * rho)):.2g}'):g} holds 40 points on a plane")
            except LidarfxError:
                pass
        raise LidarfxError("in chunks, give the radius: -r R (the default comes from the whole cloud's point "
                           f"spacing, which a chunk does not know){hint}")
    if not isinstance(references, str):
        raise LidarfxError("in chunks, references must be 'trained', 'analytic' or a references file")
    if references not in ("trained", "analytic"):
        references = os.path.abspath(references)  # the workers open it
    return {"radii": rs, "references": references, "weighting": weighting,
            "reject": DEFAULT_REJECT if reject is None else float(reject),
            "min_neighbours": DEFAULT_MIN_NEIGHBOURS if min_neighbours is None else int(min_neighbours),
            "keep_signature": bool(keep_signature)}


def eigenclass_buffer(o: dict, density: float) -> tuple[float, bool]:
    """The largest radius (exact; metres in the options, coordinate units here)."""
    from .processors import unit_of

    return float(max(o.get("radii") or [0.0])) / unit_of(o), True


def check_eigenclass_options(o: dict) -> None:
    from ..features.api import radii_list
    from ..structures import check_min_neighbours, check_reject
    from ..structures.references import resolve_references

    if not radii_list(None, o.get("radii") or []):
        raise LidarfxError("in chunks, give the radius: -r R (the default comes from the whole cloud's point spacing)")
    check_reject(o.get("reject", 3.0))
    check_min_neighbours(o.get("min_neighbours", 5))
    refs, kind = resolve_references(o.get("references", "trained"))
    refs.tables(kind, o.get("weighting", "structure"))


def eigenclass_process(chunk, ctx, o: dict):
    """Structure classes of the owned points: signatures over the buffered cloud with the
    whole cloud's index origin, then the per-point classification."""
    from ..features.api import radii_list, scale_suffix
    from ..structures import SIGNATURE, classify_signatures, structure_signatures
    from ..structures.references import resolve_references

    from .processors import unit_of

    cloud, own = chunk.cloud, chunk.own
    rs = radii_list(None, o["radii"])  # metres: the names' suffixes
    result = cloud.subset(own)
    result.meta.pop("source", None)
    rs_units = [r / unit_of(o) for r in rs]
    sig, cnt = structure_signatures(cloud.xyz, rs_units, query_xyz=cloud.xyz[own], progress=False,
                                    origin=np.asarray(ctx.mins, dtype=np.float64))
    refs, kind = resolve_references(o.get("references", "trained"))
    label, conf, dist = classify_signatures(sig, cnt, references=refs if kind == "trained" else kind,
                                            weighting=o.get("weighting", "structure"), reject=o["reject"],
                                            min_neighbours=o["min_neighbours"])
    result.update({"structure": label, "structure_confidence": conf, "structure_distance": dist})
    if o.get("keep_signature"):
        for s, r in enumerate(rs):
            sfx = "" if len(rs) == 1 else scale_suffix(r)
            for j, name in enumerate(SIGNATURE):
                result[name + sfx] = sig[:, s, j].astype(np.float32)
            result["n_neighbours" + sfx] = cnt[:, s].astype(np.float32)
    return result


# --------------------------------------------------------------------------- classify predict
NOT_LOCAL_INPUTS = {
    "intensity_norm": "the cloud's median intensity",
    "z": "the cloud's lowest z",
    "pulse_above": "pulses from the file order",
    "pulse_below": "pulses from the file order",
}
"""Per-point inputs a chunk cannot compute as the whole cloud does."""

_MODELS: dict[tuple, Any] = {}


def tile_model(o: dict):
    """The model of the run with the options' overrides (loaded once per process)."""
    from ..classify import load_model

    path = o["model"]
    try:
        st = os.stat(path)
    except OSError:
        raise LidarfxError(f"model file not found: {path}") from None
    key = (path, st.st_size, st.st_mtime_ns)
    if key not in _MODELS:
        _MODELS.clear()
        m = load_model(path)
        _MODELS[key] = (m, m.features.precomputed, m.features.ground)
    model, precomputed, ground = _MODELS[key]
    tr = model.features
    tr.precomputed = True if o.get("precomputed") else precomputed  # as run_predict: the option only switches on
    tr.ground = o.get("ground") or ground
    tr.progress = False
    return model


def _plan(model) -> tuple:
    return model.features.feature_plan()


def _limit(model, rs) -> tuple[float | None, int]:
    """The thinning density limit of the model (points per m², None: no thinning) and min_keep,
    as :meth:`LidarFeatures.feature_matrix` takes them."""
    tr = model.features
    limit = None
    if tr.max_disc_points is not None and rs:
        limit = float(tr.max_disc_points) / (math.pi * rs[0] * rs[0])
    return (limit if limit else None), int(min(tr.max_disc_points or 0, 1e9))


def check_classify_model(model, o: dict) -> None:
    """What a chunked prediction cannot do as the in-memory one does: one-line errors."""
    tr = model.features
    names, slots, point, rs = _plan(model)
    area = model.min_building_area if o.get("min_building_area") is None else float(o["min_building_area"])
    if area > 0:
        raise LidarfxError(f"the small-building rule ({area:g} m², the model's default) joins predicted-building points "
                           "over the whole cloud, which chunks do not see: give --min-building-area 0 in chunks "
                           "(or --chunk-size 0)")
    bad = [n for n in names if n in NOT_LOCAL_INPUTS]
    if bad:
        raise LidarfxError(f"the model's input {bad[0]!r} uses {NOT_LOCAL_INPUTS[bad[0]]}, which a chunk does not know; "
                           "predict with --chunk-size 0 (or train without it)")
    if slots and not tr.precomputed and tr.neighbourhood == "knn":
        raise LidarfxError("a kNN model does not run in chunks (its neighbourhoods have no fixed reach); "
                           "use --chunk-size 0")
    if "height_above_ground" in names and tr.ground != "attribute" and not tr.precomputed:
        raise LidarfxError("the model's height_above_ground comes from the ground filter, which is not local: in "
                           "chunks, run lidarfx ground IN OUT --hag first (in chunks too) and predict with "
                           "--ground attribute, or use --chunk-size 0")


def classify_options(model_path, inputs, *, ground=None, precomputed=False, confidence=False, probabilities=False,
                     min_building_area=None, max_multi_return_share=None, progress: bool | None = None) -> dict:
    """The options of a chunked ``classify predict`` run: the model and its overrides, and the
    statistics of the whole input the in-memory prediction takes from the whole cloud (computed
    here by reading the inputs once, twice when the model thins dense clouds): whether the cloud
    records return numbers (usable points), the usable points' count, the minimum of their
    coordinates in metres (the origin of the neighbour index), their density (thinning, density
    warning) and, when the model thins, the share kept and the minimum of the kept points."""
    from ..classify.pipeline import unit_to_metre
    from ..cloud import measurement_flags
    from ..io.las import iter_records, record_cloud
    from .catalog import expand_inputs

    o = {"model": os.path.abspath(model_path), "ground": ground, "precomputed": bool(precomputed),
         "confidence": bool(confidence), "probabilities": bool(probabilities),
         "min_building_area": None if min_building_area is None else float(min_building_area),
         "max_multi_return_share": None if max_multi_return_share is None else float(max_multi_return_share)}
    model = tile_model(o)
    check_classify_model(model, o)
    names, slots, point, rs = _plan(model)
    files = expand_inputs(inputs)

    def blocks():
        for p in files:
            for _, rec, header in iter_records(Path(p)):
                yield record_cloud(rec, header)

    # pass 1: return numbers anywhere? (usable points: classify.usable_mask over the whole cloud), the
    # unit, the count and coordinate bounds (metres) of the usable points, for both answers
    any_returned, units = False, set()
    total = 0
    lo = {False: np.full(3, np.inf), True: np.full(3, np.inf)}
    hi = {False: np.full(3, -np.inf), True: np.full(3, -np.inf)}
    count = {False: 0, True: 0}
    for c in blocks():
        unit_c = unit_to_metre(c)
        units.add(unit_c)
        ok, returned = measurement_flags(c.xyz, c.attrs)
        any_returned |= bool(returned is not None and returned.any())
        total += len(c)
        for flag, u in ((False, ok), (True, ok & returned if returned is not None else ok)):
            if u.any():
                xyz = c.xyz[u] * unit_c if unit_c != 1.0 else c.xyz[u]
                lo[flag] = np.minimum(lo[flag], xyz.min(axis=0))
                hi[flag] = np.maximum(hi[flag], xyz.max(axis=0))
                count[flag] += int(u.sum())
    if len(units) > 1:
        raise LidarfxError("the inputs' coordinate units differ (CRS); classify them one by one")
    unit = units.pop() if units else 1.0
    lo, hi, n = lo[any_returned], hi[any_returned], count[any_returned]

    def usable(c):
        ok, returned = measurement_flags(c.xyz, c.attrs)
        return ok & returned if (any_returned and returned is not None) else ok

    if n == 0:
        raise LidarfxError("no point of the inputs can be classified (all virtual, withheld or synthetic)")
    # pass 2: occupied 2 m squares of the usable points, from their lowest x, y (classify.pipeline.point_density)
    cells: np.ndarray = np.zeros(0, np.int64)
    span = None
    density = None
    limit, min_keep = _limit(model, rs)
    need_density = (slots and not model.features.precomputed and limit is not None) or model.training_density
    if need_density:
        span = int(math.floor((hi[1] - lo[1]) / 2.0)) + 2
        for c in blocks():
            u = usable(c)
            if not u.any():
                continue
            xy = c.xyz[u, :2] * unit if unit != 1.0 else c.xyz[u, :2]
            ij = np.floor((xy - lo[:2]) / 2.0).astype(np.int64)
            cells = np.union1d(cells, ij[:, 0] * span + ij[:, 1])
        density = float(n) / (len(cells) * 2.0 * 2.0)
    frac = None
    if slots and not model.features.precomputed and limit is not None and density > limit:
        f = max(limit / density, min(1.0, min_keep / max(n, 1)))
        frac = f if f < 1.0 else None
    origin = lo
    if frac is not None:
        if n != total:
            raise LidarfxError(f"the model thins clouds denser than {limit:.3g} points/m² (this one: {density:.3g}) and "
                               "draws the kept points over the usable ones, but the inputs hold virtual, withheld or "
                               "synthetic points: a chunk cannot know its points' draws; use --chunk-size 0")
        origin = np.full(3, np.inf)
        rng = np.random.default_rng(0)  # pipeline.thinning_mask's draws, in file order
        for c in blocks():
            keep = rng.random(len(c)) < frac
            if keep.any():
                xyz = c.xyz[keep] * unit if unit != 1.0 else c.xyz[keep]
                origin = np.minimum(origin, xyz.min(axis=0))
    if slots and not model.features.precomputed and tr_msac(model) and n != total:
        raise LidarfxError("the model's MSAC features draw per usable point, but the inputs hold virtual, withheld or "
                           "synthetic points: a chunk cannot know its points' draws; use --chunk-size 0")
    st = os.stat(o["model"])
    o.update({"model_stamp": [st.st_size, st.st_mtime_ns],  # a resumed run needs the same model
              "any_returned": any_returned, "unit": unit, "usable": n, "points": total,
              "origin": [float(v) for v in origin], "density": density, "thin": frac})
    return o


def tr_msac(model) -> bool:
    from ..features.registry import Request

    _, slots, _, _ = _plan(model)
    return Request(tuple(slots), ()).need_msac


def classify_buffer(o: dict, density: float) -> tuple[float, bool]:
    """The model's largest radius (metres) in coordinate units (exact); 0 with precomputed features."""
    model = tile_model(o)
    names, slots, point, rs = _plan(model)
    if not slots or model.features.precomputed or not rs:
        return 0.0, True
    return float(max(rs)) / float(o.get("unit") or 1.0), True


def check_classify_options(o: dict) -> None:
    if "origin" not in o:
        raise LidarfxError("classify options come from lidarfx.tiles.proc_classes.classify_options")
    check_classify_model(tile_model(o), o)


def uniform_at(ids: np.ndarray, seed: int = 0, block: int = 1 << 16) -> np.ndarray:
    """``np.random.default_rng(seed).random(N)[ids]`` without drawing the N values: the
    generator jumps to each block of ``block`` indices holding some of ``ids``."""
    ids = np.asarray(ids, dtype=np.int64)
    out = np.empty(len(ids))
    if not len(ids):
        return out
    base = np.random.default_rng(seed).bit_generator.state
    b = ids // block
    order = np.argsort(b, kind="stable")
    bs = b[order]
    cut = np.flatnonzero(np.diff(bs)) + 1
    for part in np.split(order, cut):
        k = int(b[part[0]])
        g = np.random.PCG64()
        g.state = base
        g.advance(k * block)
        r = np.random.Generator(g).random(int(ids[part].max() - k * block) + 1)
        out[part] = r[ids[part] - k * block]
    return out


def classify_process(chunk, ctx, o: dict):
    """Classes (and confidences, probabilities) of the owned points, as
    :meth:`ClassifierModel.classify` gives them with the building rule off."""
    from ..classify.pipeline import CloudSample
    from ..cloud import measurement_flags
    from ..features.api import feature_index
    from ..features.registry import Request
    from ..io.las import format_for_classes

    model = tile_model(o)
    tr = model.features
    names, slots, point, rs = _plan(model)
    cloud, own = chunk.cloud, chunk.own
    top = max(int(c) for c in model.classes.codes)
    if format_for_classes(cloud.header, top) is not None:
        raise LidarfxError(f"the model's class codes go up to {top}, which LAS point format "
                           f"{cloud.header.point_format.id} cannot store; convert the input to point format 6 "
                           "first, or use --chunk-size 0")
    ok, returned = measurement_flags(cloud.xyz, cloud.attrs)
    usable = ok & returned if (o["any_returned"] and returned is not None) else ok
    sub = cloud if usable.all() else cloud.subset(usable)
    ids = chunk.ids[usable]
    rows = np.flatnonzero(own[usable])
    unit = float(o.get("unit") or 1.0)
    m = len(rows)
    k = np.empty(m, dtype=np.int64)
    best = every = None
    if m:
        cache: dict = {}
        if slots and not tr.precomputed:
            xyz = sub.xyz if unit == 1.0 else sub.xyz * unit
            cache[("metres", id(sub))] = xyz
            keep = None if o.get("thin") is None else uniform_at(ids) < float(o["thin"])
            cache[("thin", id(sub))] = keep
            nb_xyz = xyz if keep is None else xyz[keep]
            if not len(nb_xyz):  # every neighbour thinned away: one point far above (no neighbour, as in one run)
                nb_xyz = np.asarray(o["origin"], dtype=np.float64).reshape(1, 3) + np.array([0.0, 0.0, 1e9])
            index = feature_index(nb_xyz, tr.neighbourhood, tr.k, rs, Request(tuple(slots), ()),
                                  origin=np.asarray(o["origin"], dtype=np.float64))
            cache["index"] = (id(sub), nb_xyz, index)
        X = tr.feature_matrix(CloudSample(sub, rows, ids[rows]), names, slots, point, rs, cache)
        if not (o.get("confidence") or o.get("probabilities")):
            k[:] = model.predict_matrix(X)
        else:
            proba = model.proba_matrix(X)
            k[:] = proba.argmax(axis=1)
            if o.get("probabilities"):
                every = proba.astype(np.float32)
            if o.get("confidence"):
                best = proba[np.arange(len(proba)), k].astype(np.float32)
    own_usable = usable[own]
    n_own = int(own.sum())
    codes = np.full(n_own, -1, dtype=np.int16)
    codes[own_usable] = model.classes.code_of(k)
    result = cloud.subset(own)
    result.meta.pop("source", None)
    old = result.get("classification")
    result["classification"] = np.where(codes >= 0, codes, np.asarray(old) if old is not None else 1).astype(np.uint8)
    if o.get("confidence"):
        conf = np.full(n_own, np.nan, dtype=np.float32)
        conf[own_usable] = best if best is not None else np.zeros(0, np.float32)
        result["confidence"] = conf
    if o.get("probabilities"):
        pa = np.full((n_own, len(model.classes)), np.nan, dtype=np.float32)
        if every is not None:
            pa[own_usable] = every
        for j, name in enumerate(model.probability_names()):
            result[name] = np.ascontiguousarray(pa[:, j])
    return result


PROCESSORS = {
    "eigenclass": Processor(eigenclass_buffer, eigenclass_process, check_eigenclass_options, metres=True),
    "classify": Processor(classify_buffer, classify_process, check_classify_options),
}
