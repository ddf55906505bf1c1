"""``lidarfx.report`` and ``lidarfx report``: the page's data round trip, subsampling, lines,
tables, atomic writing and the command's refusals (the browser side: test_report_browser.py)."""
from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest

import lidarfx.report as report_mod
from lidarfx import io
from lidarfx.cloud import PointCloud
from lidarfx.errors import LidarfxError
from lidarfx.report import Report, viewer_attributes
from lidarfx.report._encode import decode_attribute, encode_attribute
from lidarfx.report._html import fmt

PNG_1PX = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8DwHwAFBQIAX8jx0gAAAABJRU5ErkJggg==")


def page_data(path: Path) -> tuple[dict, dict[str, bytes], str]:
    """The viewer's JSON description, the decoded base64 blocks and the page text."""
    text = path.read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="lidarfx-meta">(.*?)</script>', text, re.S)
    meta = json.loads(m.group(1).replace("<\\/", "</")) if m else None
    blocks = {bid: base64.b64decode(body) for bid, body in
              re.findall(r'<script type="application/octet-stream" id="([^"]+)">(.*?)</script>', text, re.S)}
    return meta, blocks, text


def attribute_values(meta: dict, blocks: dict, name: str) -> np.ndarray:
    spec = next(a for a in meta["cloud"]["attributes"] if a["name"] == name)
    dtype = {"u8": "<u1", "u16": "<u2", "u32": "<u4"}[spec["type"]]
    return decode_attribute(spec, np.frombuffer(blocks[spec["block"]], dtype=dtype))


def positions(meta: dict, blocks: dict) -> np.ndarray:
    rel = np.frombuffer(blocks[meta["cloud"]["positions"]], dtype="<f4").reshape(-1, 3)
    return rel.astype(np.float64) + meta["centre"]


def mixed_cloud(n: int = 3000, seed: int = 0) -> PointCloud:
    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(0, 400, n) + 652_000.0, rng.uniform(0, 300, n) + 6_862_000.0,
                           rng.uniform(0, 40, n) + 95.0])
    planarity = rng.random(n).astype(np.float32)
    planarity[::17] = np.nan
    counted = rng.integers(0, 9, n).astype(np.float64)
    counted[::23] = np.nan
    return PointCloud(xyz, {
        "classification": rng.choice([1, 2, 6, 14], n).astype(np.uint8),
        "intensity": rng.integers(0, 4096, n).astype(np.uint16),
        "planarity": planarity,
        "gps_time": rng.uniform(3.1e8, 3.1e8 + 900.0, n),
        "segment_id": rng.integers(-5, 200_000, n).astype(np.int32),
        "scan_angle": rng.integers(-90, 90, n).astype(np.int8),
        "withheld": rng.random(n) < 0.1,
        "counted": counted,
        "normal": np.zeros(n),  # constant float
    })


def test_encoding_round_trip(tmp_path):
    cloud = mixed_cloud()
    rep = Report("round trip", max_points=10_000)
    rep.add_cloud(cloud, labels={"classification": {14: "wire"}})
    meta, blocks, text = page_data(rep.write(tmp_path))
    c = meta["cloud"]
    assert c["n_shown"] == c["n_total"] == len(cloud) and c["index"] is None
    assert np.allclose(positions(meta, blocks), cloud.xyz, rtol=0, atol=2e-4)  # float32 offsets, 400 m extent
    assert meta["centre"] == [652200.0, 6862150.0, 115.0]
    specs = {a["name"]: a for a in c["attributes"]}
    assert list(specs) == viewer_attributes(cloud)[:16] and list(specs)[0] == "classification"
    for name in ("classification", "intensity", "segment_id", "scan_angle", "withheld"):  # integers: exact
        assert np.array_equal(attribute_values(meta, blocks, name), cloud[name].astype(np.float64)), name
    assert specs["classification"]["type"] == "u8" and specs["intensity"]["type"] == "u16"
    assert specs["segment_id"]["type"] == "u32" and specs["scan_angle"]["min"] == int(cloud["scan_angle"].min())
    for name in ("planarity", "gps_time", "counted", "normal"):
        got, want = attribute_values(meta, blocks, name), cloud[name].astype(np.float64)
        assert np.array_equal(np.isnan(got), np.isnan(want)), name
        ok = ~np.isnan(want)
        assert np.max(np.abs(got[ok] - want[ok])) <= specs[name]["scale"] / 2 * (1 + 1e-9), name
    assert specs["counted"]["scale"] == 1 and specs["counted"]["nan_code"] == 255  # integral floats: exact + NaN code
    assert specs["planarity"]["type"] == "u16" and specs["planarity"]["nan_code"] == 65535
    # categories and labels
    assert specs["classification"]["kind"] == "categorical"
    assert specs["classification"]["labels"]["14"] == "wire" and specs["classification"]["labels"]["2"] == "ground"
    assert [v for v, _ in specs["classification"]["categories"]] == [1, 2, 6, 14]
    assert specs["segment_id"]["kind"] == "categorical" and specs["segment_id"]["categories"] is None
    assert specs["intensity"]["kind"] == "continuous" and specs["planarity"]["kind"] == "continuous"
    lo, hi = np.nanpercentile(cloud["planarity"], [2, 98])
    assert specs["planarity"]["lo"] == pytest.approx(lo) and specs["planarity"]["hi"] == pytest.approx(hi)
    assert c["colour_by"] == "classification"
    assert "three.js" in text and "window.lidarfxViewer" in text


def test_encode_attribute_edges():
    spec, codes = encode_attribute("v", np.array([np.inf, -np.inf, np.nan]))
    assert spec["nan_count"] == 3 and np.isnan(decode_attribute(spec, codes)).all()
    spec, codes = encode_attribute("big", np.array([0, 2**40], dtype=np.int64))  # beyond uint32: quantised
    assert spec["type"] == "u16" and decode_attribute(spec, codes)[1] == pytest.approx(2**40, rel=1e-4)
    spec, codes = encode_attribute("c", np.full(4, 0.123456))
    assert decode_attribute(spec, codes)[0] == 0.123456


def test_subsample_seeded_and_indexed(tmp_path):
    cloud = mixed_cloud(5000)
    rep = Report("sub", max_points=1200, seed=3)
    rep.add_cloud(cloud)
    meta, blocks, text = page_data(rep.write(tmp_path / "a"))
    c = meta["cloud"]
    assert c["n_shown"] == 1200 and c["n_total"] == 5000
    index = np.frombuffer(blocks[c["index"]], dtype="<u4")
    assert len(np.unique(index)) == 1200 and np.all(np.diff(index.astype(np.int64)) > 0)
    assert np.allclose(positions(meta, blocks), cloud.xyz[index], atol=2e-4)
    assert np.array_equal(attribute_values(meta, blocks, "intensity"), cloud["intensity"][index])
    assert "1,200 of 5,000 points shown" in text
    again = Report("sub", max_points=1200, seed=3)
    again.add_cloud(cloud)
    other = Report("sub", max_points=1200, seed=4)
    other.add_cloud(cloud)
    idx2 = np.frombuffer(page_data(again.write(tmp_path / "b"))[1][c["index"]], dtype="<u4")
    idx3 = np.frombuffer(page_data(other.write(tmp_path / "c"))[1][c["index"]], dtype="<u4")
    assert np.array_equal(index, idx2) and not np.array_equal(index, idx3)


def test_non_finite_points_are_not_drawn(tmp_path):
    cloud = mixed_cloud(100)
    cloud.xyz[5] = np.nan
    rep = Report("nan")
    rep.add_cloud(cloud)
    meta, blocks, _ = page_data(rep.write(tmp_path))
    index = np.frombuffer(blocks[meta["cloud"]["index"]], dtype="<u4")
    assert meta["cloud"]["n_shown"] == 99 and 5 not in index


def test_lines_share_the_cloud_centre(tmp_path):
    cloud = mixed_cloud(500)
    rep = Report("lines")
    lines = [cloud.xyz[:4] + [0, 0, 10], np.array([[652_010.0, 6_862_010.0, 120.0], [652_300.5, 6_862_200.25, 121.0]])]
    props = [{"sag": 1.25, "span": 1}, {"sag": float("nan"), "span": 2}]
    rep.add_lines("wires", lines, colour="#ff8800", properties=props)
    rep.add_cloud(cloud)  # after the lines: they are encoded at write time with the cloud's centre
    meta, blocks, text = page_data(rep.write(tmp_path))
    layer = meta["layers"][0]
    assert layer["name"] == "wires" and layer["colour"] == "#ff8800" and layer["lines"] == [[0, 4], [4, 2]]
    verts = np.frombuffer(blocks[layer["block"]], dtype="<f4").reshape(-1, 3) + np.array(meta["centre"])
    assert np.allclose(verts, np.vstack(lines), atol=2e-4)
    assert layer["properties"] == [{"sag": "1.25", "span": "1"}, {"sag": "", "span": "2"}]
    assert "wires (2 lines)" in text


def test_lines_without_cloud_and_index_page(tmp_path):
    rep = Report("lines only")
    rep.add_lines("edges", [np.array([[10.0, 20.0, 30.0], [11.0, 21.0, 31.0]])])
    meta, blocks, text = page_data(rep.write(tmp_path / "l"))
    assert meta["cloud"] is None and meta["centre"] == [10.0, 20.0, 30.0]
    assert "<th>length</th>" in text
    index = Report("index")
    index.add_link("corridor 12", "c12/index.html", "6 wires")
    index.add_table("runs", [{"name": "c12", "wires": 6}])
    meta, blocks, text = page_data(index.write(tmp_path / "i"))
    assert meta is None and not blocks and "lidarfxViewer" not in text and "three.js" not in text
    assert '<a href="c12/index.html">corridor 12</a>' in text


def test_tables_and_formatting(tmp_path):
    assert fmt(652345.678) == "652345.68" and fmt(12.345678) == "12.3457" and fmt(0.0123456) == "0.0123456"
    assert fmt(3.0) == "3" and fmt(float("nan")) == "" and fmt(float("inf")) == "" and fmt(None) == ""
    assert fmt(np.float32(0.5)) == "0.5" and fmt(np.int64(7)) == "7" and fmt(1.5e-7) == "1.5e-07"
    assert fmt(True) == "yes" and fmt([1, 2.5]) == "1, 2.5"
    rep = Report("t <&>")
    rep.add_summary({"points": 10})
    rep.add_summary({"wires": 2, "points": 12})
    rep.add_table("Spans", [{"a": 1, "b": 2.5}, {"a": float("nan"), "c": "x<y"}])
    rep.add_picture(PNG_1PX, "one pixel")
    _, _, text = page_data(rep.write(tmp_path))
    assert "<title>t &lt;&amp;&gt;</title>" in text
    summary = re.search(r'<section id="summary">(.*?)</section>', text).group(1)
    assert summary.index("points") < summary.index("wires") and ">12<" in summary
    table = re.search(r"<h2>Spans</h2>(.*?)</section>", text).group(1)
    assert re.findall(r"<th>(\w+)</th>", table) == ["a", "b", "c"]
    assert '<td class="num"></td><td></td><td>x&lt;y</td>' in table
    assert "data:image/png;base64," in text and "<figcaption>one pixel</figcaption>" in text


def test_write_is_atomic(tmp_path, monkeypatch):
    rep = Report("first")
    rep.add_cloud(mixed_cloud(50))
    page = rep.write(tmp_path)
    before = page.read_bytes()

    def broken():
        raise RuntimeError("disk full")

    monkeypatch.setattr(report_mod, "_bundle", broken)
    with pytest.raises(RuntimeError):
        rep.write(tmp_path)
    assert page.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.html"]
    (tmp_path / "file").write_text("x")
    with pytest.raises(LidarfxError, match="not a folder"):
        rep.write(tmp_path / "file")


def test_refusals(tmp_path):
    cloud = mixed_cloud(20)
    rep = Report("r")
    with pytest.raises(LidarfxError, match="unknown attribute 'nope'"):
        rep.add_cloud(cloud, ["nope"])
    with pytest.raises(LidarfxError, match="integer values"):
        rep.add_cloud(cloud, labels={"classification": {"ground": 2}})
    with pytest.raises(LidarfxError, match="colour_by"):
        rep.add_cloud(cloud, ["intensity"], colour_by="planarity")
    rep.add_cloud(cloud, ["intensity"], colour_by="z")
    with pytest.raises(LidarfxError, match="one point cloud"):
        rep.add_cloud(cloud)
    with pytest.raises(LidarfxError, match="line 1"):
        rep.add_lines("bad", [np.zeros((1, 3))])
    with pytest.raises(LidarfxError, match="non-finite"):
        rep.add_lines("bad", [np.array([[0, 0, 0], [np.nan, 0, 0]])])
    with pytest.raises(LidarfxError, match="property rows"):
        rep.add_lines("bad", [np.zeros((2, 3))], properties=[])
    with pytest.raises(LidarfxError, match="not a PNG"):
        rep.add_picture(b"GIF89a", "x")
    with pytest.raises(LidarfxError, match="no such file"):
        rep.add_picture(tmp_path / "missing.png", "x")
    with pytest.raises(LidarfxError, match="max_points"):
        Report("r", max_points=0)
    assert rep.cloud_summary["attributes"] == ["intensity"] and "planarity" in rep.cloud_summary["left_out"]


def test_default_attributes_cap_and_note(tmp_path):
    n = 50
    attrs = {f"f{k:02d}": np.arange(n, dtype=np.float32) * k for k in range(20)}
    attrs["flag"] = np.zeros(n, dtype=np.uint8)  # constant: after the varying ones
    attrs["classification"] = np.full(n, 2, dtype=np.uint8)
    cloud = PointCloud(np.random.default_rng(0).random((n, 3)), attrs)
    chosen = viewer_attributes(cloud)
    assert len(chosen) == 16 and chosen[0] == "classification" and "f00" not in chosen[:16]
    assert viewer_attributes(cloud, first=["f19"])[:2] == ["classification", "f19"]
    rep = Report("cap")
    rep.add_cloud(cloud)
    _, _, text = page_data(rep.write(tmp_path))
    assert "Not in the viewer: f00, f16, f17, f18, f19, flag" in text


# --------------------------------------------------------------------------- the command
@pytest.fixture(scope="module")
def small_laz(tmp_path_factory):
    path = tmp_path_factory.mktemp("in") / "small.laz"
    rng = np.random.default_rng(2)
    n = 3000
    xyz = np.column_stack([rng.uniform(0, 20, n) + 1000, rng.uniform(0, 10, n) + 2000, rng.uniform(0, 0.2, n) + 50])
    io.write(PointCloud(xyz, {"classification": rng.choice([2, 6], n).astype(np.uint8),
                              "intensity": rng.integers(0, 500, n).astype(np.uint16)}), path)
    return path


def test_cli_report(small_laz, tmp_path, run_cli):
    out = tmp_path / "rep"
    rc, stdout, err = run_cli(["report", str(small_laz), str(out), "--json", "--max-points", "1000",
                               "--attributes", "intensity,classification", "--colour-by", "intensity"])
    assert rc == 0, err
    s = json.loads(stdout)
    assert s["points"] == 3000 and s["shown"] == 1000 and s["attributes"] == ["intensity", "classification"]
    assert s["output"] == str(out / "index.html") and s["bytes"] == (out / "index.html").stat().st_size
    meta, blocks, text = page_data(out / "index.html")
    assert meta["cloud"]["colour_by"] == "intensity" and "data:image/png;base64," in text
    assert "lidarfx report " in text and "--max-points 1000" in text


@pytest.mark.slow  # compiles the feature kernels when numba's cache is cold
def test_cli_report_features(small_laz, tmp_path, run_cli):
    rc, stdout, err = run_cli(["report", str(small_laz), str(tmp_path / "f"), "--features", "planarity,verticality",
                               "-r", "1.0", "--no-picture", "--json", "-q"])
    assert rc == 0, err
    s = json.loads(stdout)
    assert s["features"] == ["planarity", "verticality"]
    assert s["attributes"][:3] == ["classification", "planarity", "verticality"]


@pytest.mark.parametrize("argv, message", [
    (["{missing}", "{out}"], "file not found"),
    (["{laz}", "{nofolder}/rep"], "parent does not exist"),
    (["{laz}", "{afile}"], "is not a folder"),
    (["{laz}", "{out}", "--features", "eigen"], "needs a radius"),
    (["{laz}", "{out}", "--max-points", "0"], "--max-points must be"),
    (["{laz}", "{out}", "-r", "-1"], "radii must be positive"),
    (["{laz}", "{out}", "--attributes", "nope"], "unknown attribute 'nope'"),
    (["{laz}", "{out}", "--attributes", "a,,b"], "comma-separated"),
    (["{laz}", "{out}", "--colour-by", "nope"], "colour_by 'nope'"),
    (["{laz}", "{out}", "-r", "0.5", "--features", "bogus"], "bogus"),
])
def test_cli_refusals(small_laz, tmp_path, run_cli, argv, message):
    afile = tmp_path / "afile"
    afile.write_text("x")
    paths = {"missing": tmp_path / "missing.laz", "out": tmp_path / "out", "laz": small_laz,
             "nofolder": tmp_path / "no" / "such", "afile": afile}
    rc, stdout, err = run_cli(["report", *[a.format(**paths) for a in argv], "-q", "--no-picture"])
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("lidarfx: error:") and message in err, err
    assert not (tmp_path / "out").exists() and stdout == ""


def test_cli_help_has_examples(run_cli):
    rc, stdout, _ = run_cli(["report", "--help"])
    assert rc == 0 and "examples:" in stdout and "lidarfx report scan.laz" in stdout
