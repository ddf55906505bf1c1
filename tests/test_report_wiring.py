"""``--report OUTDIR`` on the analysis commands: the page holds the command's cloud, its
products as viewer layers, its figures and pictures; it is checked before the work and refused
for chunked runs."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lidarfx import io, synth
from lidarfx.cli import main
from test_report import attribute_values, page_data, positions


@pytest.fixture(scope="module")
def house(tmp_path_factory):
    path = tmp_path_factory.mktemp("house") / "house.laz"
    io.write(synth.house(seed=0), path)
    return path


def test_edges_report_has_the_lines_and_the_classes(house, tmp_path, capsys):
    out = tmp_path / "lines.geojson"
    assert main(["edges", str(house), str(out), "--report", str(tmp_path / "rep"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["outputs"]["report"] == str(tmp_path / "rep" / "index.html")
    meta, blocks, text = page_data(tmp_path / "rep" / "index.html")
    features = json.loads(out.read_text())["features"]
    layer = next(la for la in meta["layers"] if la["name"] == "edge lines")
    assert len(layer["lines"]) == len(features) == summary["lines"] > 0
    # the first line's vertices are the GeoJSON's
    verts = np.frombuffer(blocks[layer["block"]], dtype="<f4").reshape(-1, 3) + np.array(meta["centre"])
    start, count = layer["lines"][0]
    assert np.allclose(verts[start:start + count], np.array(features[0]["geometry"]["coordinates"]), atol=1e-3)
    cloud = io.read(house)
    assert meta["cloud"]["n_total"] == meta["cloud"]["n_shown"] == len(cloud)
    assert np.allclose(positions(meta, blocks), cloud.xyz, atol=1e-3)
    structure = attribute_values(meta, blocks, "structure")
    assert set(np.unique(structure)) <= set(range(-1, 8)) and (structure >= 0).any()
    assert "edge lines over the points" in text  # the picture drawn for the report
    assert f">{summary['candidates']}<" in text.replace(",", "")


def test_features_report_keeps_the_streamed_values(house, tmp_path):
    out = tmp_path / "fx.laz"
    assert main(["features", str(house), str(out), "-r", "0.5", "-f", "planarity,verticality", "-q",
                 "--report", str(tmp_path / "rep")]) == 0
    meta, blocks, _ = page_data(tmp_path / "rep" / "index.html")
    got = io.read(out)
    for name in ("planarity", "verticality"):
        page = attribute_values(meta, blocks, name)
        ref = np.asarray(got[name], dtype=np.float64)
        finite = np.isfinite(ref)
        assert np.array_equal(np.isfinite(page), finite)
        span = np.nanmax(ref) - np.nanmin(ref)
        assert np.max(np.abs(page[finite] - ref[finite])) <= span / 65000 + 1e-7


def test_report_folder_checked_before_the_work(house, tmp_path):
    blocker = tmp_path / "rep"
    blocker.write_text("a file")
    res = subprocess.run([sys.executable, "-m", "lidarfx", "edges", str(house), str(tmp_path / "l.geojson"),
                          "--report", str(blocker)], capture_output=True, text=True)
    assert res.returncode == 2 and res.stderr.strip() == f"lidarfx: error: {blocker} exists and is not a folder"
    assert not (tmp_path / "l.geojson").exists()


def test_chunked_run_refuses_a_report(house, tmp_path, capsys):
    rc = main(["features", str(house), str(tmp_path / "o.laz"), "-r", "0.5", "--chunk-size", "5",
               "--report", str(tmp_path / "rep")])
    assert rc == 2
    assert "--report is written by runs in memory" in capsys.readouterr().err
    assert not (tmp_path / "rep").exists() and not (tmp_path / "o.laz").exists()


def test_powerlines_report_draws_each_conductor(tmp_path):
    scene = synth.powerline(n_spans=1, n_trees=2, n_near_trees=0, seed=3)
    src = tmp_path / "corridor.laz"
    io.write(scene, src)
    assert main(["powerlines", str(src), str(tmp_path / "out"), "-q", "--report", str(tmp_path / "rep")]) == 0
    meta, blocks, text = page_data(tmp_path / "rep" / "index.html")
    wires = json.loads((tmp_path / "out" / "wires.json").read_text())["conductors"]
    layer = next(la for la in meta["layers"] if la["name"] == "catenaries")
    assert len(layer["lines"]) == len(wires) == len(scene.meta["truth"]["wires"])
    assert "wires.png" in text and "conductor table" in text
    cls = attribute_values(meta, blocks, "classification")
    assert (cls == 14).sum() > 0.9 * (np.asarray(scene["classification"]) == 14).sum()
