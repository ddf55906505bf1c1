"""Vector-layer writers: GeoJSON (and its reader), DXF, CSV, vertices CSV, JSON, export_lines."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lidarfx.errors import LidarfxError
from lidarfx.vector import (
    Polyline,
    crs_name,
    export_lines,
    read_geojson,
    write_csv,
    write_dxf,
    write_geojson,
    write_json,
    write_vertices_csv,
)
from lidarfx.vector import export as vexport

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"
LA93 = REAL / "test_data_77050_627755_LA93_IGN69.laz"

EPSG_2154 = {"wkt": None, "epsg": 2154, "geographic": False, "unit_to_metre": 1.0}


def _lines() -> list[Polyline]:
    edge = Polyline(np.array([[770500.12345, 6277550.98765, 101.23456],
                              [770510.0, 6277550.98765, 101.5],
                              [770510.0, 6277560.0, 102.0]]),
                    support=57, rms=0.0213, kind="edge", attrs={"building": 3, "label": "roof"})
    ring = Polyline(np.array([[0.0, 0.0, 10.0], [4.0, 0.0, 10.0], [4.0, 3.0, 10.0], [0.0, 3.0, 10.0]]),
                    support=120, rms=math.nan, kind="border", closed=True, attrs={"building": 4, "flat": True})
    wire = Polyline(np.array([[1.0, 2.0, 30.0], [101.0, 2.0, 25.0]]), support=8, kind="wire",
                    attrs={"sag": 1.25})
    return [edge, ring, wire]


# ------------------------------------------------------------------ CRS
def test_crs_name_epsg_wkt_none():
    assert crs_name(EPSG_2154) == "urn:ogc:def:crs:EPSG::2154"
    assert crs_name({"wkt": "whatever", "epsg": "32631"}) == "urn:ogc:def:crs:EPSG::32631"
    assert crs_name(None) is None
    assert crs_name({"wkt": None, "epsg": None}) is None
    assert crs_name(4326) == "urn:ogc:def:crs:EPSG::4326"
    assert crs_name("urn:ogc:def:crs:EPSG::2154") == "urn:ogc:def:crs:EPSG::2154"  # read_geojson's name back
    with pytest.raises(LidarfxError):
        crs_name(2.5)


def test_crs_name_from_wkt_via_pyproj():
    import pyproj
    wkt = pyproj.CRS.from_epsg(2154).to_wkt()
    assert crs_name({"wkt": wkt, "epsg": None, "geographic": False, "unit_to_metre": 1.0}) \
        == "urn:ogc:def:crs:EPSG::2154"


def test_crs_name_unknown_wkt_is_passed_through():
    # a WKT no EPSG code matches (nor pyproj can parse) is written as it is: GDAL reads any SRS text
    assert crs_name({"wkt": "  LOCAL_CS[\"site grid\"]  ", "epsg": None}) == 'LOCAL_CS["site grid"]'


def test_crs_name_from_real_la93_header():
    if not LA93.exists():
        pytest.skip(f"real data not found: {LA93} (../shared/data/real)")
    import lidarfx
    from lidarfx.crs import cloud_crs

    crs = cloud_crs(lidarfx.read(LA93))
    assert crs is not None and crs["epsg"] == 2154
    assert crs_name(crs) == "urn:ogc:def:crs:EPSG::2154"
    # the WKT alone (no EPSG key) gives the same code through pyproj
    assert crs_name({**crs, "epsg": None}) == "urn:ogc:def:crs:EPSG::2154"


# ------------------------------------------------------------------ GeoJSON
def test_geojson_content(tmp_path):
    out = write_geojson(_lines(), tmp_path / "lines.geojson", crs=EPSG_2154, meta={"run": "t", "k": np.int64(3)})
    assert out == tmp_path / "lines.geojson"
    text = out.read_text()
    assert "NaN" not in text
    data = json.loads(text)
    assert data["type"] == "FeatureCollection"
    assert data["crs"] == {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::2154"}}
    assert data["lidarfx"] == {"run": "t", "k": 3}
    f = data["features"]
    assert len(f) == 3
    assert all(x["type"] == "Feature" and x["geometry"]["type"] == "LineString" for x in f)
    assert all(len(pos) == 3 for x in f for pos in x["geometry"]["coordinates"])
    # rounding to 3 decimals
    assert f[0]["geometry"]["coordinates"][0] == [770500.123, 6277550.988, 101.235]
    # closed ring repeats its first vertex
    c = f[1]["geometry"]["coordinates"]
    assert len(c) == 5 and c[0] == c[-1] == [0.0, 0.0, 10.0]
    assert len(f[2]["geometry"]["coordinates"]) == 2
    p0, p1 = f[0]["properties"], f[1]["properties"]
    assert p0["id"] == 0 and f[2]["properties"]["id"] == 2
    assert p0["kind"] == "edge" and p0["support"] == 57 and p0["rms"] == 0.0213
    assert p0["n_vertices"] == 3 and p0["closed"] is False
    assert p0["building"] == 3 and p0["label"] == "roof"
    assert p0["length_2d"] == pytest.approx(9.87655 + 9.01235, abs=1e-4)
    assert p1["rms"] is None  # NaN → null
    assert p1["closed"] is True and p1["flat"] is True
    assert p1["length"] == pytest.approx(14.0) and p1["z_min"] == p1["z_max"] == 10.0


def test_geojson_precision_and_no_crs(tmp_path):
    write_geojson(_lines()[:1], tmp_path / "a.geojson", precision=1)
    data = json.loads((tmp_path / "a.geojson").read_text())
    assert "crs" not in data and "lidarfx" not in data
    assert data["features"][0]["geometry"]["coordinates"][0] == [770500.1, 6277551.0, 101.2]
    with pytest.raises(LidarfxError, match="precision"):
        write_geojson(_lines(), tmp_path / "b.geojson", precision=-1)
    assert not (tmp_path / "b.geojson").exists()


def test_geojson_round_trip(tmp_path):
    lines = _lines()
    write_geojson(lines, tmp_path / "rt.geojson", crs=EPSG_2154)
    back, name = read_geojson(tmp_path / "rt.geojson")
    assert name == "urn:ogc:def:crs:EPSG::2154"
    assert len(back) == len(lines)
    for a, b in zip(lines, back):
        np.testing.assert_allclose(b.vertices, a.vertices, atol=1e-3, rtol=0)
        assert b.kind == a.kind and b.closed == a.closed and b.support == a.support
        assert b.attrs == a.attrs  # built-in properties and id do not leak into attrs
    assert back[0].rms == pytest.approx(0.0213)
    assert math.isnan(back[1].rms)
    assert back[1].n_vertices == 4  # the repeated first vertex is dropped
    # written again from what was read: same coordinates and properties (lengths now of the rounded vertices)
    write_geojson(back, tmp_path / "rt2.geojson", crs=name)
    one, two = (json.loads((tmp_path / f).read_text()) for f in ("rt.geojson", "rt2.geojson"))
    assert two["crs"] == one["crs"]
    for f1, f2 in zip(one["features"], two["features"]):
        assert f2["geometry"] == f1["geometry"]
        p1, p2 = f1["properties"], f2["properties"]
        assert p2.keys() == p1.keys()
        for k in p1:
            assert p2[k] == (pytest.approx(p1[k], abs=2e-3) if k in ("length", "length_2d", "z_min", "z_max") else p1[k])


def test_read_geojson_2d_multilinestring_and_skips(tmp_path):
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"kind": "breakline", "name": "dyke", "tags": [1, 2], "id": 9},
         "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1], [2, 0]]}},
        {"type": "Feature", "properties": None,
         "geometry": {"type": "MultiLineString", "coordinates": [[[0, 0, 1], [1, 0, 1]],
                                                                  [[5, 5, 2], [6, 5, 2], [6, 6, 2], [5, 5, 2]]]}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [0, 0]}},
        {"type": "Feature", "properties": {}, "geometry": None},
    ]}
    (tmp_path / "in.geojson").write_text(json.dumps(doc))
    lines, name = read_geojson(tmp_path / "in.geojson")
    assert name is None
    assert len(lines) == 3
    a, b, c = lines
    assert a.kind == "breakline" and a.attrs == {"name": "dyke", "z_missing": True}  # list attr dropped, id too
    np.testing.assert_array_equal(a.vertices, [[0, 0, 0], [1, 1, 0], [2, 0, 0]])
    assert a.closed is False and a.support == 0 and math.isnan(a.rms)
    assert b.kind == "line" and b.attrs == {} and not b.closed and b.n_vertices == 2
    assert c.closed is True and c.n_vertices == 3
    np.testing.assert_array_equal(c.vertices[-1], [6, 6, 2])


def test_read_geojson_errors(tmp_path):
    with pytest.raises(LidarfxError, match="not found"):
        read_geojson(tmp_path / "missing.geojson")
    (tmp_path / "bad.geojson").write_text("{not json")
    with pytest.raises(LidarfxError, match="not a JSON file") as e:
        read_geojson(tmp_path / "bad.geojson")
    assert "\n" not in str(e.value)
    (tmp_path / "bin.geojson").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(LidarfxError, match="not a JSON file"):
        read_geojson(tmp_path / "bin.geojson")
    (tmp_path / "feat.geojson").write_text(json.dumps({"type": "Feature", "geometry": None}))
    with pytest.raises(LidarfxError, match="not a GeoJSON FeatureCollection"):
        read_geojson(tmp_path / "feat.geojson")
    (tmp_path / "list.geojson").write_text("[1, 2]")
    with pytest.raises(LidarfxError, match="not a GeoJSON FeatureCollection"):
        read_geojson(tmp_path / "list.geojson")
    one = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": [[0, 0, 0]]}}]}
    (tmp_path / "one.geojson").write_text(json.dumps(one))
    with pytest.raises(LidarfxError, match="feature 0"):
        read_geojson(tmp_path / "one.geojson")
    with pytest.raises(LidarfxError, match="not a file"):
        read_geojson(tmp_path)


def test_read_geojson_refuses_large_file_before_reading(tmp_path, monkeypatch):
    big = tmp_path / "big.geojson"
    with open(big, "wb") as fh:  # sparse: 201 MB, no data written
        fh.truncate(201 * 1024 * 1024)

    def no_read(*a, **k):
        raise AssertionError("the file must not be opened")
    monkeypatch.setattr(vexport, "open", no_read, raising=False)
    with pytest.raises(LidarfxError, match="200 MB"):
        read_geojson(big)


# ------------------------------------------------------------------ DXF
def test_dxf_content(tmp_path):
    import ezdxf
    lines = _lines() + [Polyline(np.array([[0, 0, 0], [1, 1, 1.0]]), kind="tower/member")]
    write_dxf(lines, tmp_path / "lines.dxf")
    doc = ezdxf.readfile(tmp_path / "lines.dxf")
    assert doc.header["$INSUNITS"] == 6
    polys = list(doc.modelspace().query("POLYLINE"))
    assert len(polys) == 4
    assert all(p.is_3d_polyline for p in polys)
    assert [p.dxf.layer for p in polys] == ["EDGE", "BORDER", "WIRE", "TOWER_MEMBER"]
    np.testing.assert_allclose([v.dxf.location for v in polys[0].vertices], lines[0].vertices, atol=1e-9)
    np.testing.assert_allclose([v.dxf.location for v in polys[1].vertices], lines[1].vertices, atol=1e-9)
    assert polys[1].is_closed and not polys[0].is_closed and not polys[2].is_closed
    assert len(polys[1].vertices) == 4  # closed by the flag, no repeated vertex
    names = {"EDGE", "BORDER", "WIRE", "TOWER_MEMBER"}
    assert names <= {layer.dxf.name for layer in doc.layers}
    colours = [doc.layers.get(n).color for n in sorted(names)]
    assert len(set(colours)) == 4


def test_dxf_fixed_layer_and_empty(tmp_path):
    import ezdxf
    write_dxf(_lines(), tmp_path / "one.dxf", layer="Lidar lines")
    doc = ezdxf.readfile(tmp_path / "one.dxf")
    assert {p.dxf.layer for p in doc.modelspace().query("POLYLINE")} == {"Lidar lines"}
    with pytest.raises(LidarfxError, match="layer"):
        write_dxf(_lines(), tmp_path / "bad.dxf", layer="a/b")
    assert not (tmp_path / "bad.dxf").exists()
    write_dxf([], tmp_path / "empty.dxf")
    doc = ezdxf.readfile(tmp_path / "empty.dxf")
    assert len(doc.modelspace()) == 0 and doc.header["$INSUNITS"] == 6


# ------------------------------------------------------------------ CSV
def _read_csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.reader(fh))


def test_csv_content(tmp_path):
    write_csv(_lines(), tmp_path / "lines.csv")
    rows = _read_csv(tmp_path / "lines.csv")
    head = rows[0]
    assert head == ["id", "kind", "n_vertices", "length", "length_2d", "support", "rms", "z_min", "z_max",
                    "closed", "x_start", "y_start", "z_start", "x_end", "y_end", "z_end",
                    "building", "label", "flat", "sag"]
    recs = [dict(zip(head, r)) for r in rows[1:]]
    assert len(recs) == 3
    e, r, w = recs
    assert e["id"] == "0" and e["kind"] == "edge" and e["n_vertices"] == "3" and e["support"] == "57"
    assert float(e["rms"]) == 0.0213 and e["closed"] == "false"
    assert float(e["x_start"]) == 770500.123 and float(e["y_start"]) == 6277550.988
    assert float(e["z_start"]) == 101.235 and float(e["z_min"]) == 101.235 and float(e["z_max"]) == 102.0
    assert [float(e[k]) for k in ("x_end", "y_end", "z_end")] == [770510.0, 6277560.0, 102.0]
    assert e["building"] == "3" and e["label"] == "roof" and e["flat"] == "" and e["sag"] == ""
    assert r["rms"] == "" and r["closed"] == "true" and float(r["length"]) == 14.0
    assert r["flat"] == "true" and r["label"] == ""
    assert [float(r[k]) for k in ("x_end", "y_end", "z_end")] == [0.0, 3.0, 10.0]  # last vertex, not the repeat
    assert w["sag"] == "1.25" and w["building"] == "" and float(w["length_2d"]) == 100.0
    assert float(w["length"]) == pytest.approx(math.hypot(100.0, 5.0), abs=1e-4)


def test_csv_attr_clashing_with_a_column_is_refused(tmp_path):
    line = Polyline(np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]], attrs={"x_start": 1})
    with pytest.raises(LidarfxError, match="x_start"):
        write_csv([line], tmp_path / "c.csv")
    assert list(tmp_path.iterdir()) == []


def test_vertices_csv(tmp_path):
    write_vertices_csv(_lines(), tmp_path / "v.csv", precision=2)
    rows = _read_csv(tmp_path / "v.csv")
    assert rows[0] == ["id", "vertex", "x", "y", "z"]
    assert len(rows) == 1 + 3 + 4 + 2
    assert rows[1] == ["0", "0", "770500.12", "6277550.99", "101.23"]
    assert rows[4] == ["1", "0", "0.0", "0.0", "10.0"]
    assert rows[7] == ["1", "3", "0.0", "3.0", "10.0"]
    assert rows[-1] == ["2", "1", "101.0", "2.0", "25.0"]


# ------------------------------------------------------------------ JSON
def test_json_content(tmp_path):
    write_json(_lines(), tmp_path / "l.json", meta={"threshold": 0.5, "bad": math.nan})
    text = (tmp_path / "l.json").read_text()
    assert "NaN" not in text
    data = json.loads(text)
    assert data["meta"] == {"threshold": 0.5, "bad": None}
    assert [d["id"] for d in data["lines"]] == [0, 1, 2]
    e, r, _ = data["lines"]
    assert e["kind"] == "edge" and e["support"] == 57 and e["building"] == 3
    assert e["vertices"][0] == [770500.123, 6277550.988, 101.235]
    assert r["closed"] is True and len(r["vertices"]) == 4 and r["rms"] is None
    write_json([], tmp_path / "e.json")
    assert json.loads((tmp_path / "e.json").read_text()) == {"meta": {}, "lines": []}


# ------------------------------------------------------------------ export_lines, folders, empty
def test_export_lines_all_formats(tmp_path):
    out = export_lines(_lines(), geojson=tmp_path / "a.geojson", dxf=tmp_path / "a.dxf", csv=tmp_path / "a.csv",
                       json=tmp_path / "a.json", crs=EPSG_2154, meta={"run": 1})
    assert out == {"geojson": str(tmp_path / "a.geojson"), "dxf": str(tmp_path / "a.dxf"),
                   "csv": str(tmp_path / "a.csv"), "json": str(tmp_path / "a.json")}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "a.dxf", "a.geojson", "a.json"]
    g = json.loads((tmp_path / "a.geojson").read_text())
    assert g["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::2154" and g["lidarfx"] == {"run": 1}
    assert json.loads((tmp_path / "a.json").read_text())["meta"] == {"run": 1}
    assert len(_read_csv(tmp_path / "a.csv")) == 4
    assert export_lines(_lines()) == {}


def test_export_lines_bad_second_folder_writes_nothing(tmp_path):
    with pytest.raises(LidarfxError, match="output folder does not exist"):
        export_lines(_lines(), geojson=tmp_path / "a.geojson", dxf=tmp_path / "nope" / "a.dxf",
                     csv=tmp_path / "a.csv")
    assert list(tmp_path.iterdir()) == []


def test_export_lines_failing_writer_leaves_no_output(tmp_path):
    # the JSON writer refuses an attribute named "vertices" after GeoJSON, DXF and CSV were written
    bad = _lines() + [Polyline(np.array([[0, 0, 0], [1, 0, 0.0]]), attrs={"vertices": 2})]
    with pytest.raises(LidarfxError, match="vertices"):
        export_lines(bad, geojson=tmp_path / "a.geojson", dxf=tmp_path / "a.dxf", csv=tmp_path / "a.csv",
                     json=tmp_path / "a.json")
    assert list(tmp_path.iterdir()) == []


def test_export_lines_same_path_twice_is_refused(tmp_path):
    with pytest.raises(LidarfxError, match="same file"):
        export_lines(_lines(), geojson=tmp_path / "a.out", csv=tmp_path / "a.out")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("writer", [write_geojson, write_dxf, write_csv, write_vertices_csv, write_json])
def test_writers_refuse_missing_folder(tmp_path, writer):
    with pytest.raises(LidarfxError, match="output folder does not exist"):
        writer(_lines(), tmp_path / "missing" / "out.x")
    with pytest.raises(LidarfxError, match="is a folder"):
        writer(_lines(), tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("writer", [write_geojson, write_dxf, write_csv, write_vertices_csv, write_json])
def test_writers_refuse_non_polylines(tmp_path, writer):
    with pytest.raises(LidarfxError, match="Polyline"):
        writer([np.zeros((2, 3))], tmp_path / "out.x")
    assert list(tmp_path.iterdir()) == []


def test_empty_list_writes_valid_files(tmp_path):
    write_geojson([], tmp_path / "e.geojson", crs=EPSG_2154)
    data = json.loads((tmp_path / "e.geojson").read_text())
    assert data["type"] == "FeatureCollection" and data["features"] == []
    assert read_geojson(tmp_path / "e.geojson") == ([], "urn:ogc:def:crs:EPSG::2154")
    write_csv([], tmp_path / "e.csv")
    assert _read_csv(tmp_path / "e.csv") == [list(vexport._CSV_COLUMNS)]
    write_vertices_csv([], tmp_path / "v.csv")
    assert _read_csv(tmp_path / "v.csv") == [["id", "vertex", "x", "y", "z"]]
    out = export_lines([], geojson=tmp_path / "x.geojson", dxf=tmp_path / "x.dxf")
    assert set(out) == {"geojson", "dxf"} and (tmp_path / "x.dxf").stat().st_size > 0


def test_failed_write_keeps_previous_file(tmp_path):
    target = tmp_path / "keep.geojson"
    target.write_text("old")
    with pytest.raises(LidarfxError):
        write_geojson(_lines(), target, meta="not a dict")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.geojson"]
