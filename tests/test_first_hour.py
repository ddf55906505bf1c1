"""Frictions of a first hour with lidarfx: usage errors, reference classes, tables."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from lidarfx import io, synth
from lidarfx.cli import main


def test_usage_errors_are_one_line(tmp_path):
    def err(*argv: str) -> list[str]:
        res = subprocess.run([sys.executable, "-m", "lidarfx", *argv], capture_output=True, text=True, cwd=tmp_path)
        assert res.returncode == 2
        return res.stderr.strip().splitlines()

    assert err("features", "a.laz", "b.laz", "-r", "abc") == [
        "lidarfx features: error: argument -r/--radius: invalid float value: 'abc' (see lidarfx features --help)"]
    assert err("features", "a.laz", "b.laz", "--bogus") == [
        "lidarfx: error: unrecognized arguments: --bogus (see lidarfx --help)"]


def test_ground_eval_takes_several_reference_classes(tmp_path, capsys):
    scene = synth.terrain(size=60.0, seed=2)
    cls = np.asarray(scene["classification"]).copy()
    ground = np.flatnonzero(cls == 2)
    water = ground[: len(ground) // 5]
    cls[water] = 9  # a fifth of the ground is water: still ground of the reference
    scene["classification"] = cls
    path = tmp_path / "a_rather_long_file_name_for_a_table_of_results_tile_0001.laz"
    io.write(scene, path)

    def total(spec: str) -> dict:
        assert main(["ground-eval", str(path), "--reference-class", spec, "--json", "-q"]) == 0
        return json.loads(capsys.readouterr().out)

    both, only2 = total("2,9"), total("2")
    assert both["reference_class"] == [2, 9]
    row2, row29 = only2["files"][0], both["files"][0]
    # with 2 alone, the water points the filter calls ground count as type II errors
    assert row29["n_type_ii"] < row2["n_type_ii"] - 0.5 * len(water)
    assert row29["total"] < row2["total"]
    assert main(["ground-eval", str(path), "--reference-class", "2,9", "-q"]) == 0
    assert str(path) in capsys.readouterr().out  # the table keeps the whole path


def test_dtm_ascii_grid_gets_a_prj_from_an_epsg_code(tmp_path):
    from lidarfx.ground.raster import Raster

    r = Raster(np.zeros((3, 4), np.float32), (500_000.0, 5_400_000.0), 1.0, {"epsg": 25832, "wkt": None})
    r.write(tmp_path / "dtm.asc")
    prj = (tmp_path / "dtm.prj").read_text()
    assert prj.startswith("PROJCS[") and "ETRS_1989_UTM_Zone_32N" in prj
    wkt = Raster(np.zeros((2, 2), np.float32), (0.0, 0.0), 1.0, {"wkt": prj})
    wkt.write(tmp_path / "b.asc")
    assert (tmp_path / "b.prj").read_text() == prj
    Raster(np.zeros((2, 2), np.float32), (0.0, 0.0), 1.0, None).write(tmp_path / "c.asc")
    assert not (tmp_path / "c.prj").exists()
