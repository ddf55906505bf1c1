"""Tables printed on a terminal never cut a path, a class name or a feature name: on a narrow
terminal (COLUMNS=60) every long value still appears whole in the output (the line is longer than
the terminal rather), as the path column of ``ground-eval`` does (tests/test_first_hour.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import lidarfx
from lidarfx.cloud import PointCloud

LONG_CLASSES = {"bare_earth_and_low_ground_surface_points": 2, "high vegetation trees hedges and tall bushes": 5,
                "buildings_roofs_walls_and_their_annexes": 6}


@pytest.fixture(scope="module")
def long_model(tmp_path_factory):
    """A tiny random forest (eigen features at r = 1.25 m, 5 trees) trained on a synthetic cloud
    whose class names and folder and file names are long."""
    from lidarfx.classify import train

    d = tmp_path_factory.mktemp("tables") / "a_rather_long_folder_name_for_the_training_data_of_the_2026_survey"
    d.mkdir()
    rng = np.random.default_rng(0)
    n = 3000
    xy = rng.random((n, 2)) * 30
    cls = np.where(xy[:, 0] < 10, 2, np.where(xy[:, 0] < 20, 5, 6)).astype(np.uint8)
    z = np.where(cls == 2, 0.0, np.where(cls == 5, rng.random(n) * 8, 6.0)) + rng.normal(0, 0.02, n)
    tile = d / "training_tile_with_a_very_long_descriptive_name_north_east_0001.laz"
    lidarfx.write(PointCloud(np.column_stack([xy + [500_000, 5_000_000], z]), {"classification": cls}), tile)
    spec = ",".join(f"{name}={code}" for name, code in LONG_CLASSES.items())
    model = train([tile], classes=spec, features=["eigen"], radii=[1.25], classifier="rf", n_estimators=5,
                  max_per_class=300, terrain_augment=0)
    path = d / "model_with_a_long_name_for_the_2026_survey_of_the_old_town.skops"
    model.save(path)
    return path, tile, model


@pytest.mark.parametrize("command", [["classify", "info"], ["info"]])
def test_classify_info_keeps_whole_paths_and_names(long_model, run_cli, monkeypatch, command):
    path, tile, model = long_model
    monkeypatch.setenv("COLUMNS", "60")
    rc, out, err = run_cli([*command, str(path)])
    assert rc == 0, err
    lines = out.splitlines()
    assert any(str(path) in line for line in lines)  # whole, on one line
    assert any(str(tile) in line for line in lines)
    for name in LONG_CLASSES:
        assert sum(name in line for line in lines) >= 2  # the class and its training sample
    assert model.feature_names and all(any(f in line for line in lines) for f in model.feature_names)
    assert "classifier (rf)" in out and "training density" in out
    # the classes as a table: names padded to the longest, then the codes
    rows = [line for line in lines if any(name in line and "codes" in line for name in LONG_CLASSES)]
    assert len(rows) == 3 and len({line.index("codes") for line in rows}) == 1
    # --json is unchanged: the whole summary
    rc, out, _ = run_cli(["classify", "info", str(path), "--json"])
    assert rc == 0 and json.loads(out)["features"] == model.feature_names


def _fake_demo(long_scene: str, out_dir):
    figures = [{"measure": "share of the true ridge, eave and verge lines covered within 0.25 m", "value": 0.9731,
                "target": ">= 0.90 of every true line's length (ridge, eaves, verges, hips)", "pass": True},
               {"measure": "plan RMS of the breaklines against the dike's true crest and toe lines", "value": 0.31,
                "target": "<= 0.25 m", "pass": False}]
    rec = {"name": long_scene, "title": "A house", "points": 12_345, "seconds": 1.5, "passed": False,
           "figures": figures, "files": {}, "report": str(out_dir / "house" / "index.html")}
    return {"scenes": [rec], "index": str(out_dir / "index.html"), "seconds": 1.5}


def test_demo_summary_keeps_whole_measures_targets_and_paths(tmp_path, run_cli, monkeypatch):
    import lidarfx.demo

    out_dir = tmp_path / "a_rather_long_output_folder_name_for_the_lidarfx_demo_report_pages"
    long_scene = "house_with_a_scene_name_much_longer_than_a_narrow_terminal"
    res = _fake_demo(long_scene, out_dir)
    monkeypatch.setattr(lidarfx.demo, "run_demo", lambda out, scenes, seed=None, progress=None: res)
    monkeypatch.setenv("COLUMNS", "60")
    rc, _, err = run_cli(["demo", "--out", str(out_dir), "--scenes", "house"])
    assert rc == 0, err
    lines = err.splitlines()
    wanted = [long_scene, str(out_dir / "index.html"), f"-> {out_dir}/"]
    wanted += [f["measure"] for f in res["scenes"][0]["figures"]] + [f["target"] for f in res["scenes"][0]["figures"]]
    for text in wanted:
        assert any(text in line for line in lines), text
    assert any("0.9731" in line and "ok" in line for line in lines)
    assert any("missed" in line for line in lines)
    assert json.loads((out_dir / "summary.json").read_text())["scenes"][0]["name"] == long_scene
