"""Everyday operations on real files against independent computations: crop (ray casting and
segment distances in numpy), merge (laspy records), outliers (scipy cKDTree), reproject (pyproj on
the raw coordinates); chunked runs equal the in-memory ones; bad input is a one-line error."""
from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx.errors import LidarfxError

REAL = Path(__file__).resolve().parents[2] / "shared/data/real"
IGN = [REAL / f"test_data_770{k}_627755_LA93_IGN69.laz" for k in ("50", "55", "60")]


def real(name: str) -> Path:
    p = REAL / name
    if not p.exists():
        pytest.skip(f"real test file {p} is missing (the shared data folder is not mounted)")
    return p


def _one_line_error(rc, err, *needles):
    assert rc == 2, err
    lines = [ln for ln in err.strip().splitlines() if ln.strip() and "warning" not in ln]
    assert len(lines) == 1 and lines[0].startswith("lidarfx: error: "), err
    for n in needles:
        assert n in lines[0], lines[0]


def _same_records(a: laspy.LasData, b_array: np.ndarray) -> None:
    assert a.points.array.dtype == b_array.dtype
    assert np.array_equal(a.points.array, b_array)


# --------------------------------------------------------------------------- crop references
def _even_odd(x, y, rings) -> np.ndarray:
    """Crossing number over all rings (holes included, any winding)."""
    inside = np.zeros(len(x), dtype=bool)
    for r in rings:
        r = np.asarray(r, dtype=np.float64)[:, :2]
        if not np.array_equal(r[0], r[-1]):
            r = np.vstack([r, r[:1]])
        for (xa, ya), (xb, yb) in zip(r[:-1], r[1:]):
            cross = (ya > y) != (yb > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                xi = xa + (y - ya) * (xb - xa) / (yb - ya)
            inside ^= cross & (x < xi)
    return inside


def _distance_to_rings(x, y, rings) -> np.ndarray:
    d = np.full(len(x), np.inf)
    for r in rings:
        r = np.asarray(r, dtype=np.float64)[:, :2]
        for (xa, ya), (xb, yb) in zip(r[:-1], r[1:]):
            dx, dy = xb - xa, yb - ya
            t = np.clip(((x - xa) * dx + (y - ya) * dy) / max(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
            d = np.minimum(d, np.hypot(x - (xa + t * dx), y - (ya + t * dy)))
    return d


def _shapefile_records(path):
    import shapefile

    with shapefile.Reader(str(path)) as r:
        out = []
        for s in r.shapes():
            pts = np.asarray(s.points)
            cuts = list(s.parts) + [len(pts)]
            out.append([pts[a:b] for a, b in zip(cuts[:-1], cuts[1:])])
    return out


def test_crop_shapefile_polygons_match_ray_casting(tmp_path, run_cli):
    src, shp = real("lake.laz"), real("lake_breakline.shp")
    las = laspy.read(src)
    x, y = np.asarray(las.x), np.asarray(las.y)
    records = _shapefile_records(shp)
    inside = np.zeros(len(x), dtype=bool)
    d = np.full(len(x), np.inf)  # plan distance to the rings
    for rings in records:
        inside |= _even_odd(x, y, rings)
        d = np.minimum(d, _distance_to_rings(x, y, rings))
    assert (d == 0).sum() >= 1 and not (inside | (d == 0)).sum() - inside.sum() > 10
    inside |= d == 0  # a point on the boundary is inside
    assert 1000 < inside.sum() < len(x) // 2
    rc, out, err = run_cli(["crop", str(src), str(tmp_path / "in.laz"), "--polygon", str(shp), "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["kept"] == int(inside.sum()) and s["area"]["polygons"] == 3
    _same_records(laspy.read(tmp_path / "in.laz"), las.points.array[inside])  # every field, bit for bit
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "out.laz"), "--polygon", str(shp), "--invert", "-q"])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "out.laz"), las.points.array[~inside])
    # 5 m around the lake, and 2 m inside its shore: exact plan distances to the rings
    near = inside | (d <= 5.0)
    deep = inside & (d >= 2.0)
    for buf, want in ((5.0, near), (-2.0, deep)):
        rc, out, err = run_cli(["crop", str(src), str(tmp_path / f"b{buf}.laz"), "--polygon", str(shp),
                                f"--buffer={buf}", "--json"])
        assert rc == 0, err
        ambiguous = np.abs(d - abs(buf)) < 1e-9
        got = np.zeros(len(x), dtype=bool)
        got_xy = laspy.read(tmp_path / f"b{buf}.laz")
        key = lambda a: a["X"].astype(np.int64) * 10**9 + a["Y"].astype(np.int64)  # noqa: E731
        got[np.isin(key(las.points.array), key(got_xy.points.array))] = True
        assert not ambiguous.any() and np.array_equal(got, want)


def test_crop_geojson_multipolygon_with_hole_and_crs(tmp_path, run_cli):
    src = real(IGN[0].name)
    las = laspy.read(src)
    x, y = np.asarray(las.x), np.asarray(las.y)
    x0, y0 = 770500.0037, 6277500.0041
    outer = [[x0 + 5, y0 + 5], [x0 + 35, y0 + 5], [x0 + 35, y0 + 45], [x0 + 5, y0 + 45], [x0 + 5, y0 + 5]]
    hole = [[x0 + 15, y0 + 15], [x0 + 15, y0 + 30], [x0 + 25, y0 + 30], [x0 + 25, y0 + 15], [x0 + 15, y0 + 15]]
    tri = [[x0 + 36, y0 + 1], [x0 + 41.3, y0 + 1.7], [x0 + 40.1, y0 + 12.9], [x0 + 36, y0 + 1]]
    doc = {"type": "FeatureCollection", "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::2154"}},
           "features": [{"type": "Feature", "properties": {},
                         "geometry": {"type": "MultiPolygon", "coordinates": [[outer, hole], [tri]]}}]}
    area = tmp_path / "area.geojson"
    area.write_text(json.dumps(doc))
    want = _even_odd(x, y, [outer, hole]) | _even_odd(x, y, [tri])
    assert _even_odd(x, y, [tri]).sum() > 10 and (_even_odd(x, y, [outer]) & ~_even_odd(x, y, [outer, hole])).sum() > 10
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "c.las"), "--polygon", str(area)])
    assert rc == 0, err
    got = laspy.read(tmp_path / "c.las")
    assert got.header.parse_crs().to_epsg() == 2154
    _same_records(got, las.points.array[want])
    # the same crop in chunks: the same points
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "t.las"), "--polygon", str(area), "--chunk-size", "20",
                          "--workers", "1", "-q"])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "t.las"), las.points.array[want])
    # an area in another CRS is refused
    doc["crs"]["properties"]["name"] = "urn:ogc:def:crs:EPSG::32631"
    (tmp_path / "utm.geojson").write_text(json.dumps(doc))
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "u.las"), "--polygon", str(tmp_path / "utm.geojson")])
    _one_line_error(rc, err, "EPSG:32631", "EPSG:2154")
    assert not (tmp_path / "u.las").exists()


def test_crop_box_with_z_and_feet_buffer(tmp_path, run_cli):
    src = real(IGN[1].name)
    las = laspy.read(src)
    x, y, z = np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)
    b = (770560.0, 6277510.0, 770590.0, 6277540.0, 22.0, 30.0)
    want = (x >= b[0]) & (x <= b[2]) & (y >= b[1]) & (y <= b[3]) & (z >= b[4]) & (z <= b[5])
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "box.laz"), "--bounds", ",".join(map(str, b))])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "box.laz"), las.points.array[want])
    # a file in US survey feet: --buffer 3 m widens the box by 3 / 0.3048006 ft
    feet = real("file_with_both_wkt_and_geotiff_vlrs.las")
    fl = laspy.read(feet)
    fx, fy = np.asarray(fl.x), np.asarray(fl.y)
    box = (2445190.0, 604310.0, 2445210.0, 604330.0)
    w = 3.0 / (1200 / 3937)
    want = (fx >= box[0] - w) & (fx <= box[2] + w) & (fy >= box[1] - w) & (fy <= box[3] + w)
    assert 0 < want.sum() < len(fx) and want.sum() > ((fx >= box[0]) & (fx <= box[2]) & (fy >= box[1]) & (fy <= box[3])).sum()
    rc, _, err = run_cli(["crop", str(feet), str(tmp_path / "f.las"), "--bounds", ",".join(map(str, box)),
                          "--buffer", "3"])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "f.las"), fl.points.array[want])


def test_crop_bad_input(tmp_path, run_cli):
    src = real("lake.laz")
    # a shapefile of lines, a GeoJSON of a line, a file that is no GeoJSON
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--polygon", str(real("TO_city_hall.shp"))])
    _one_line_error(rc, err, "POLYLINEZ", "polygon")
    line = tmp_path / "line.geojson"
    line.write_text(json.dumps({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}))
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--polygon", str(line)])
    _one_line_error(rc, err, "LineString", "Polygon or MultiPolygon")
    bad = tmp_path / "bad.geojson"
    bad.write_text("{not json")
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--polygon", str(bad)])
    _one_line_error(rc, err, "not a GeoJSON")
    bow = tmp_path / "bow.geojson"
    bow.write_text(json.dumps({"type": "Polygon", "coordinates": [[[0, 0], [2, 2], [2, 0], [0, 2], [0, 0]]]}))
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--polygon", str(bow)])
    _one_line_error(rc, err, "invalid polygon", "Self-intersection")
    # nothing inside: exit 2 and no file; --allow-empty writes an empty file with the header
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--bounds", "-10,-10,10,10"])
    _one_line_error(rc, err, "no point", "nothing written", "476941")
    assert not (tmp_path / "o.laz").exists()
    rc, out, err = run_cli(["crop", str(src), str(tmp_path / "e.laz"), "--bounds", "0,0,1,1", "--allow-empty", "--json"])
    assert rc == 0 and json.loads(out)["kept"] == 0, err
    e = laspy.read(tmp_path / "e.laz")
    assert len(e.points) == 0 and e.header.point_format.id == laspy.read(src).header.point_format.id
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "e.laz"), "--bounds", "0,0,1,1", "--allow-empty"])
    _one_line_error(rc, err, "exists", "--force")  # an existing output needs --force, checked before any work
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "e.laz"), "--bounds", "0,0,1,1", "--allow-empty", "--force",
                          "-q"])
    assert rc == 0, err
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz"), "--bounds", "5,0,1,1"])
    _one_line_error(rc, err, "minimum exceeds")
    rc, _, err = run_cli(["crop", str(src), str(tmp_path / "o.laz")])
    assert rc == 2 and "--bounds" in err


# --------------------------------------------------------------------------- merge
def test_merge_tiles_streamed_is_the_concatenation(tmp_path, run_cli):
    files = [real(p.name) for p in IGN]
    ins = [laspy.read(f) for f in files]
    rc, out, err = run_cli(["merge", *map(str, files), str(tmp_path / "all.laz"), "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["mode"] == "streamed" and s["points"] == sum(len(f.points) for f in ins)
    assert all(s["las"]["coordinates_exact"].values())
    m = laspy.read(tmp_path / "all.laz")
    _same_records(m, np.concatenate([f.points.array for f in ins]))
    assert m.header.parse_crs().to_epsg() == 2154 and m.header.global_encoding.wkt
    assert np.allclose(m.header.mins, np.min([f.header.mins for f in ins], axis=0))


def _copy_as(src: laspy.LasData, path: Path, *, point_format: int, version: str, scales, offsets, n: int,
             shift=(0.0, 0.0, 0.0), extra: dict | None = None, crs=None) -> laspy.LasData:
    """A new file holding the first n points of src in another format / scale / offset (laspy only)."""
    h = laspy.LasHeader(version=version, point_format=point_format)
    for name, dtype in (extra or {}).items():
        h.add_extra_dim(laspy.ExtraBytesParams(name=name, type=dtype))
    h.scales, h.offsets = np.asarray(scales, dtype=float), np.asarray(offsets, dtype=float)
    if crs is not None:
        h.add_crs(crs)
    out = laspy.LasData(h)
    out.x = np.asarray(src.x[:n]) + shift[0]
    out.y = np.asarray(src.y[:n]) + shift[1]
    out.z = np.asarray(src.z[:n]) + shift[2]
    for dim in ("intensity", "return_number", "number_of_returns", "classification", "user_data", "point_source_id"):
        out[dim] = np.asarray(src[dim][:n])
    if "scan_angle" in out.point_format.dimension_names:
        out["scan_angle"] = np.round(np.asarray(src["scan_angle_rank"][:n], dtype=float) / 0.006).astype(np.int16)
    for name in (extra or {}):
        out[name] = np.arange(n) % 7
    out.write(path)
    return laspy.read(path)


def test_merge_reconciles_formats_scales_offsets(tmp_path, run_cli):
    from pyproj import CRS

    a_path, b_src = real("samp11-utm.laz"), laspy.read(real("samp21-utm.laz"))
    a = laspy.read(a_path)
    # samp21 as LAS 1.4 point format 6 with a finer scale, other offsets, WKT for the same CRS, an extra dimension
    b = _copy_as(b_src, tmp_path / "b.las", point_format=6, version="1.4", scales=[0.001] * 3,
                 offsets=[512000.0, 5403000.0, 100.0], n=3000, extra={"tree": np.int16}, crs=CRS.from_epsg(32632))
    rc, out, err = run_cli(["merge", str(a_path), str(tmp_path / "b.las"), str(tmp_path / "m.laz"), "--json"])
    assert rc == 0, err
    s = json.loads(out)["las"]
    assert s["point_format"] == 6 and s["version"] == "1.4" and s["scales"] == [0.001] * 3
    assert s["crs"].startswith("EPSG:32632") and all(s["coordinates_exact"].values())
    m = laspy.read(tmp_path / "m.laz")
    na = len(a.points)
    assert len(m.points) == na + len(b.points)
    for axis in "xyz":
        want = np.concatenate([np.asarray(a[axis]), np.asarray(b[axis])])
        assert np.abs(np.asarray(m[axis]) - want).max() <= 0.0005 + 1e-9
    for dim in ("intensity", "return_number", "number_of_returns", "classification", "user_data", "point_source_id",
                "synthetic", "key_point", "withheld"):
        assert np.array_equal(np.asarray(m[dim]), np.concatenate([np.asarray(a[dim]), np.asarray(b[dim])])), dim
    assert np.abs(np.asarray(m.scan_angle[:na]) * 0.006 - np.asarray(a.scan_angle_rank)).max() <= 0.003 + 1e-9
    assert np.array_equal(np.asarray(m.scan_angle[na:]), np.asarray(b.scan_angle))
    assert np.array_equal(np.asarray(m["tree"][na:]), np.asarray(b["tree"])) and not np.asarray(m["tree"][:na]).any()
    # in memory (PLY input forces it): the same points and fields as the streamed merge
    from lidarfx.merge import merge_clouds

    mem = merge_clouds([lidarfx.read(a_path), lidarfx.read(tmp_path / "b.las")])
    lidarfx.write(mem, tmp_path / "mem.laz")
    _same_records(laspy.read(tmp_path / "mem.laz"), m.points.array)


def test_merge_refuses_incompatible_files(tmp_path, run_cli):
    from pyproj import CRS

    rc, _, err = run_cli(["merge", str(real("samp11-utm.laz")), str(real("fusa.laz")), str(tmp_path / "m.laz")])
    _one_line_error(rc, err, "EPSG:32632", "EPSG:32754", "fusa.laz")
    assert not (tmp_path / "m.laz").exists()
    # one extra-dimension name, two types: refused naming the field and both files
    mc = laspy.read(real("MixedConifer.laz"))
    _copy_as(mc, tmp_path / "int_tree.las", point_format=1, version="1.2", scales=[0.01] * 3,
             offsets=mc.header.offsets, n=500, extra={"treeID": np.int32}, crs=CRS.from_epsg(26912))
    rc, _, err = run_cli(["merge", str(real("MixedConifer.laz")), str(tmp_path / "int_tree.las"), str(tmp_path / "m.laz")])
    _one_line_error(rc, err, "'treeID'", "float64", "int32", "MixedConifer.laz", "int_tree.las")
    # an extent the finest scale cannot hold in 32-bit integers
    s11 = laspy.read(real("samp11-utm.laz"))
    _copy_as(s11, tmp_path / "far.las", point_format=0, version="1.2", scales=[0.0001] * 3,
             offsets=[1_500_000.0, 5_400_000.0, 0.0], n=200, shift=(1_000_000.0, 0.0, 0.0), crs=CRS.from_epsg(32632))
    rc, _, err = run_cli(["merge", str(real("samp11-utm.laz")), str(tmp_path / "far.las"), str(tmp_path / "m.laz")])
    _one_line_error(rc, err, "does not fit 32-bit", "0.0001")
    assert not (tmp_path / "m.laz").exists()


def test_merge_of_las_1_0_and_of_a_header_without_bounds(tmp_path, run_cli):
    """A LAS 1.0 input (laspy writes no 1.0) merges into LAS 1.1 with the same points; a header whose
    bounds are NaN takes its bounds from the points."""
    import struct

    src = real("TO_core_last_zoom.laz")
    assert str(laspy.open(src).header.version) == "1.0"
    rc, _, err = run_cli(["merge", str(src), str(tmp_path / "m.laz"), "-q"])
    assert rc == 0, err
    a, b = laspy.read(src), laspy.read(tmp_path / "m.laz")
    assert str(b.header.version) == "1.1" and b.header.point_format.id == a.header.point_format.id
    assert np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y) and np.array_equal(a.z, b.z)
    assert np.array_equal(a.classification, b.classification) and np.array_equal(a.gps_time, b.gps_time)
    # the same file uncompressed, its header's max x / min x (bytes 179-194) set to NaN
    las_path = tmp_path / "nan_bounds.las"
    lidarfx.write(lidarfx.read(src), las_path)  # LAS 1.2 (laspy writes no 1.0)
    raw = bytearray(las_path.read_bytes())
    raw[179:195] = struct.pack("<2d", float("nan"), float("nan"))
    las_path.write_bytes(bytes(raw))
    rc, _, err = run_cli(["merge", str(las_path), str(real("TO_core_last_zoom.laz")), str(tmp_path / "m2.laz"), "-q"])
    assert rc == 0, err
    c = lidarfx.read(tmp_path / "m2.laz")
    assert len(c) == 2 * len(a) and np.allclose(c.xyz[: len(a)], np.column_stack([a.x, a.y, a.z]), atol=1e-9)


# --------------------------------------------------------------------------- outliers
def _sor_reference(xyz, k, std):
    from scipy.spatial import cKDTree

    d, _ = cKDTree(xyz).query(xyz, k + 1)
    md = d[:, 1:].mean(axis=1)
    thr = md.mean() + std * md.std(ddof=1)
    return md, thr


def test_statistical_outliers_against_ckdtree(tmp_path, run_cli):
    src = real("samp11-utm.laz")
    las = laspy.read(src)
    xyz = np.column_stack([las.x, las.y, las.z])
    md, thr = _sor_reference(xyz, 8, 2.0)
    assert not (np.abs(md - thr) < 1e-9 * thr).any()  # no point on the threshold: the answer is unambiguous
    want = md > thr
    assert 100 < want.sum() < len(xyz) // 10
    from lidarfx.outliers import mean_knn_distance

    assert np.allclose(mean_knn_distance(xyz, 8), md, rtol=1e-12, atol=1e-12)
    rc, out, err = run_cli(["filter", str(src), str(tmp_path / "c.laz"), "--outliers", "statistical", "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["outliers"] == int(want.sum()) and abs(s["threshold"] - thr) <= 1e-12 * thr
    c = laspy.read(tmp_path / "c.laz")
    cls = np.asarray(las.classification).copy()
    cls[want] = 7
    assert np.array_equal(np.asarray(c.classification), cls)
    for dim in las.point_format.dimension_names:  # every other field unchanged
        if dim != "classification":
            assert np.array_equal(np.asarray(c[dim]), np.asarray(las[dim])), dim
    # drop, --k / --std, and the chunked run (two passes) equal to the in-memory one, bit for bit
    md12, thr12 = _sor_reference(xyz, 12, 1.5)
    rc, _, err = run_cli(["filter", str(src), str(tmp_path / "d.laz"), "--outliers", "statistical", "--k", "12",
                          "--std", "1.5", "--action", "drop"])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "d.laz"), las.points.array[~(md12 > thr12)])
    rc, out, err = run_cli(["filter", str(src), str(tmp_path / "t.laz"), "--outliers", "statistical", "--k", "12",
                            "--std", "1.5", "--action", "drop", "--chunk-size", "80", "--workers", "1", "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["buffer_widened_m"] > 10 and s["kept"] == int((md12 <= thr12).sum())  # gaps: the default buffer grew
    _same_records(laspy.read(tmp_path / "t.laz"), las.points.array[~(md12 > thr12)])
    # a buffer the user gives is kept: too narrow is a one-line error naming the buffer needed
    rc, _, err = run_cli(["filter", str(src), str(tmp_path / "u.laz"), "--outliers", "statistical", "--chunk-size", "80",
                          "--buffer", "2", "--workers", "1"])
    _one_line_error(rc, err, "nearest neighbours reach", "give --buffer")
    assert not (tmp_path / "u.laz").exists()


def test_radius_outliers_against_ckdtree(tmp_path, run_cli):
    from scipy.spatial import cKDTree

    src = real("samp21-utm.laz")
    las = laspy.read(src)
    xyz = np.column_stack([las.x, las.y, las.z])
    r, n = 1.5, 2
    tree = cKDTree(xyz)
    others = tree.query_ball_point(xyz, r, return_length=True) - 1
    want = others < n
    assert 0 < want.sum() < len(xyz)
    rc, out, err = run_cli(["filter", str(src), str(tmp_path / "r.laz"), "--outliers", "radius", "--radius", str(r),
                            "--min-neighbours", str(n), "--class", "18", "--json"])
    assert rc == 0, err
    assert json.loads(out)["outliers"] == int(want.sum())
    got = np.asarray(laspy.read(tmp_path / "r.laz").classification)
    exp = np.asarray(las.classification).copy()
    exp[want] = 18
    assert np.array_equal(got, exp)
    rc, _, err = run_cli(["filter", str(src), str(tmp_path / "t.laz"), "--outliers", "radius", "--radius", str(r),
                          "--min-neighbours", str(n), "--class", "18", "--chunk-size", "50", "--workers", "1", "-q"])
    assert rc == 0, err
    _same_records(laspy.read(tmp_path / "t.laz"), laspy.read(tmp_path / "r.laz").points.array)
    rc, _, err = run_cli(["filter", str(src), str(tmp_path / "x.laz"), "--outliers", "radius", "--radius", "1"])
    _one_line_error(rc, err, "--min-neighbours")


def test_outlier_moments_are_exact_in_any_order():
    from lidarfx.outliers import moments, threshold

    rng = np.random.default_rng(3)
    d = np.abs(rng.lognormal(0.0, 1.5, 20_001))
    n, s1, s2 = moments(d)
    parts = [moments(p) for p in np.array_split(rng.permutation(d), 7)]
    assert (sum(p[0] for p in parts), sum(p[1] for p in parts), sum(p[2] for p in parts)) == (n, s1, s2)
    from fractions import Fraction

    few = d[:2000]
    assert moments(few)[1:] == (sum(map(Fraction, few.tolist())), sum(Fraction(v) ** 2 for v in few.tolist()))
    mu, sigma, thr = threshold(n, s1, s2, 2.0)
    assert abs(mu - d.mean()) <= 1e-14 * mu and abs(sigma - d.std(ddof=1)) <= 1e-12 * sigma


# --------------------------------------------------------------------------- reproject
def test_reproject_to_geographic_against_pyproj(tmp_path, run_cli):
    import pyproj
    from pyproj import Transformer

    src = real(IGN[2].name)
    las = laspy.read(src)
    rc, out, err = run_cli(["reproject", str(src), str(tmp_path / "g.laz"), "--to", "EPSG:4326", "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["from"].startswith("EPSG:2154") and s["to"].startswith("EPSG:4326")
    g = laspy.read(tmp_path / "g.laz")
    assert g.header.parse_crs().to_epsg() == 4326 and g.header.global_encoding.wkt
    lon, lat = Transformer.from_crs(2154, 4326, always_xy=True).transform(np.asarray(las.x), np.asarray(las.y))
    sc = g.header.scales
    assert sc[0] <= 1e-7  # about a centimetre or finer
    assert np.abs(np.asarray(g.x) - lon).max() <= sc[0] / 2 + 1e-12
    assert np.abs(np.asarray(g.y) - lat).max() <= sc[1] / 2 + 1e-12
    assert np.array_equal(g.points.array["Z"], las.points.array["Z"])  # heights untouched, raw values too
    assert np.array_equal(np.asarray(g.classification), np.asarray(las.classification))
    assert np.array_equal(np.asarray(g.red), np.asarray(las.red)) and np.array_equal(g.gps_time, las.gps_time)
    # in chunks: the same coordinates within the output scale
    rc, _, err = run_cli(["reproject", str(src), str(tmp_path / "t.laz"), "--to", "EPSG:4326", "--chunk-size", "20",
                          "--workers", "1", "-q"])
    assert rc == 0, err
    t = laspy.read(tmp_path / "t.laz")
    assert np.abs(np.asarray(t.x) - lon).max() <= t.header.scales[0] / 2 + 1e-12
    assert np.array_equal(np.asarray(t.intensity), np.asarray(las.intensity))
    assert not pyproj.network.is_network_enabled()


def test_reproject_legacy_file_geotiff_keys(tmp_path, run_cli):
    from pyproj import Transformer

    src = real("samp11-utm.laz")
    las = laspy.read(src)
    rc, _, err = run_cli(["reproject", str(src), str(tmp_path / "e.las"), "--to", "EPSG:25832", "-q"])
    assert rc == 0, err
    e = laspy.read(tmp_path / "e.las")
    assert str(e.header.version) == "1.2" and e.header.point_format.id == 0
    keys = {k.id: k.value_offset for v in e.header.vlrs if isinstance(v, laspy.vlrs.known.GeoKeyDirectoryVlr)
            for k in v.geo_keys}
    assert keys[3072] == 25832 and keys[1024] == 1 and keys[3076] == 9001
    from lidarfx.io import info

    assert info(tmp_path / "e.las")["crs"]["epsg"] == 25832
    ex, ey = Transformer.from_crs(32632, 25832, always_xy=True).transform(np.asarray(las.x), np.asarray(las.y))
    assert np.abs(np.asarray(e.x) - ex).max() <= e.header.scales[0] / 2 + 1e-9
    assert np.abs(np.asarray(e.y) - ey).max() <= e.header.scales[1] / 2 + 1e-9


def test_reproject_compound_heights_feet_to_metres(tmp_path, run_cli):
    from pyproj import Transformer

    src = real("file_with_both_wkt_and_geotiff_vlrs.las")
    las = laspy.read(src)
    rc, out, err = run_cli(["reproject", str(src), str(tmp_path / "m.las"), "--from", "EPSG:6880+6360",
                            "--to", "EPSG:6343+5703", "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["vertical"] == "heights transformed"
    m = laspy.read(tmp_path / "m.las")
    ex, ey, ez = Transformer.from_crs("EPSG:6880+6360", "EPSG:6343+5703", always_xy=True).transform(
        np.asarray(las.x), np.asarray(las.y), np.asarray(las.z))
    for got, want, sc in ((m.x, ex, m.header.scales[0]), (m.y, ey, m.header.scales[1]), (m.z, ez, m.header.scales[2])):
        assert np.abs(np.asarray(got) - want).max() <= sc / 2 + 1e-9
    assert np.allclose(ez, np.asarray(las.z) * 1200 / 3937, atol=1e-6)  # NAVD88 ftUS -> m, no grid
    from lidarfx.io import info

    crs = info(tmp_path / "m.las")["crs"]
    assert crs["unit_to_metre"] == 1.0 and "NAVD88" in crs["wkt"]


def test_reproject_refusals(tmp_path, run_cli):
    import warnings

    from pyproj.transformer import TransformerGroup

    src = real(IGN[0].name)
    rc, _, err = run_cli(["reproject", str(src), str(tmp_path / "o.laz"), "--to", "EPSG:99999"])
    _one_line_error(rc, err, "EPSG:99999")
    rc, _, err = run_cli(["reproject", str(real("lake.laz")), str(tmp_path / "o.laz"), "--to", "EPSG:4326"])
    _one_line_error(rc, err, "no CRS", "--from")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        have_grid = TransformerGroup("EPSG:2154+5720", "EPSG:4979", always_xy=True).best_available
    if not have_grid:  # the geoid grid is not installed: refused by name, never a silent 2-D transform
        rc, _, err = run_cli(["reproject", str(src), str(tmp_path / "o.laz"), "--from", "EPSG:2154+5720",
                              "--to", "EPSG:4979"])
        _one_line_error(rc, err, "fr_ign_RAF18.tif", "projsync")
    rc, _, err = run_cli(["reproject", str(src), str(tmp_path / "o.laz"), "--from", "EPSG:2154+5720",
                          "--to", "EPSG:2154+5719"])
    _one_line_error(rc, err, "ballpark")
    assert not (tmp_path / "o.laz").exists()
    from lidarfx.reproject import reproject

    with pytest.raises(LidarfxError, match="scale"):
        reproject(lidarfx.read(src), "EPSG:4326", scale=-1)


# --------------------------------------------------------------------------- the commands
@pytest.mark.parametrize("command", ["crop", "merge", "filter", "reproject"])
def test_help_has_examples(run_cli, command):
    rc, out, _ = run_cli([command, "--help"])
    assert rc == 0 and "examples:" in out and f"lidarfx {command} " in out and "docs/everyday.md" in out


def test_python_api_on_clouds():
    from lidarfx.crop import crop
    from lidarfx.merge import merge_clouds
    from lidarfx.outliers import filter_outliers
    from lidarfx.reproject import reproject

    cloud = lidarfx.read(real("samp41-utm.laz"))
    x0, y0 = cloud.xyz[:, :2].min(axis=0)
    part = crop(cloud, bounds=(x0, y0, x0 + 50, y0 + 50))
    rest = crop(cloud, bounds=(x0, y0, x0 + 50, y0 + 50), invert=True)
    assert len(part) + len(rest) == len(cloud) and len(part) > 0
    both = merge_clouds([part, rest])
    assert len(both) == len(cloud) and set(both.names) >= set(cloud.names)
    clean = filter_outliers(cloud, "radius", radius=2.0, min_neighbours=1, action="drop")
    assert clean.meta["outliers"]["outliers"] == len(cloud) - len(clean)
    geo = reproject(cloud, "EPSG:4326")
    assert geo.meta["reproject"]["to"].startswith("EPSG:4326") and np.all(np.abs(geo.xyz[:, 0]) < 180)
    with pytest.raises(LidarfxError, match="exactly one"):
        crop(cloud)
