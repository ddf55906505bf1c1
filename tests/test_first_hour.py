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
    from lidarfx.surface.raster import Raster

    r = Raster(np.zeros((3, 4), np.float32), (500_000.0, 5_400_000.0), 1.0, {"epsg": 25832, "wkt": None})
    r.write(tmp_path / "dtm.asc")
    prj = (tmp_path / "dtm.prj").read_text()
    assert prj.startswith("PROJCS[") and "ETRS_1989_UTM_Zone_32N" in prj
    wkt = Raster(np.zeros((2, 2), np.float32), (0.0, 0.0), 1.0, {"wkt": prj})
    wkt.write(tmp_path / "b.asc")
    assert (tmp_path / "b.prj").read_text() == prj
    Raster(np.zeros((2, 2), np.float32), (0.0, 0.0), 1.0, None).write(tmp_path / "c.asc")
    assert not (tmp_path / "c.prj").exists()


# ---------------------------------------------------------------- progress by expected time
class _FakeProgress:
    started: list = []

    def __init__(self, *a, **k):
        self.tasks = {}

    def start(self):
        _FakeProgress.started.append(self)

    def stop(self):
        pass

    def add_task(self, description, total=None, completed=0):
        self.tasks[0] = [description, total, completed]
        return 0

    def advance(self, task, k):
        self.tasks[task][2] += k


def test_a_bar_appears_when_the_work_will_take_long_whatever_its_size(monkeypatch):
    """Before: a bar only for 2 M points or more (a 90 s run on fewer points showed nothing).
    Now: by the rate after AUTO_AFTER seconds."""
    from lidarfx import progress

    monkeypatch.setattr(progress, "_progress", lambda spinner=False: _FakeProgress())
    _FakeProgress.started = []
    now = [0.0]
    # 1000 small units, 10 ms each: 10 s expected -> a bar once AUTO_AFTER has passed
    with progress.bar("slow", 1000, None, clock=lambda: now[0]) as advance:
        for _ in range(1000):
            now[0] += 0.01
            advance(1)
    assert len(_FakeProgress.started) == 1
    assert _FakeProgress.started[0].tasks[0][2] == 1000  # it counts from where the work was
    _FakeProgress.started = []
    now[0] = 0.0
    # 10 M points in 0.2 s: no bar however many points
    with progress.bar("fast", 10_000_000, None, clock=lambda: now[0]) as advance:
        for _ in range(100):
            now[0] += 0.002
            advance(100_000)
    assert _FakeProgress.started == []
    with progress.bar("forced", 5, True) as advance:
        advance(5)
    assert len(_FakeProgress.started) == 1
    with progress.bar("never", 5, False, clock=lambda: now[0]) as advance:
        now[0] += 100
        advance(1)
    assert len(_FakeProgress.started) == 1


def test_a_stage_shows_a_spinner_only_when_it_lasts(monkeypatch):
    import time

    from lidarfx import progress

    monkeypatch.setattr(progress, "_progress", lambda spinner=False: _FakeProgress())
    _FakeProgress.started = []
    with progress.stage("quick", None, delay=0.3):
        pass
    time.sleep(0.4)
    assert _FakeProgress.started == []
    with progress.stage("long", None, delay=0.05):
        time.sleep(0.3)
    assert [p.tasks[0][0] for p in _FakeProgress.started] == ["long"]
    assert progress.wanted(None) in (None, False) and progress.wanted(True) is True and progress.wanted(False) is False


def test_cross_validation_names_each_fold_in_its_spinner(monkeypatch):
    """`classify evaluate --cv` fits once per fold; each fit shows a spinner naming the fold (and
    none when progress is off)."""
    from lidarfx import progress
    from lidarfx.classify import TrainConfig
    from lidarfx.classify.evaluate import cross_validate

    monkeypatch.setattr(progress, "_progress", lambda spinner=False: _FakeProgress())
    monkeypatch.setattr(progress, "AUTO_AFTER", 0.0)
    rng = np.random.default_rng(0)
    X = rng.normal(size=(600, 3))
    y = (X[:, 0] > 0).astype(np.int64)
    folds = np.arange(600) % 3
    cfg = TrainConfig(classifier="rf", n_estimators=5)
    _FakeProgress.started = []
    cross_validate(X, y, folds, cfg, 2, progress=True)
    names = [p.tasks[0][0] for p in _FakeProgress.started]
    assert [n.split(":")[0] for n in names] == ["fold 1 of 3", "fold 2 of 3", "fold 3 of 3"], names
    _FakeProgress.started = []
    cross_validate(X, y, folds, cfg, 2, progress=False)
    assert _FakeProgress.started == []


# ---------------------------------------------------------------- segmentation that fits the cloud
def test_segment_stops_with_a_hint_that_works_when_nothing_is_found(run_cli, tmp_path):
    """Before: `lidarfx segment` on an ALS cloud (a few points per m²) found 0 segments with the
    dense-TLS defaults and exited 0.  Now it stops (exit 2, nothing written) naming the point
    spacing and parameters from it, and those parameters find the roof planes."""
    import re
    import shlex

    from lidarfx import io, synth

    src = tmp_path / "house.laz"
    io.write(synth.house(density=4.0, wall_density=0.5, seed=1), src)
    out = tmp_path / "seg.laz"
    rc, stdout, err = run_cli(["segment", str(src), str(out), "-q"])
    assert rc == 2 and not out.exists()
    assert len(err.strip().splitlines()) == 1 and "no plane segment found" in err
    m = re.search(r"about ([0-9.]+) m apart", err)
    assert m and 0.3 < float(m.group(1)) < 0.8  # 4 pts/m² on the roof: 0.5 m
    opts = shlex.split(err.split("try ", 1)[1])
    rc, stdout, err = run_cli(["segment", str(src), str(out), "--json", *opts])
    assert rc == 0, err
    import json

    summary = json.loads(stdout)
    seg = io.read(out)
    z = seg.xyz[:, 2]
    roof = (np.asarray(seg["classification"]) == synth.HOUSE_CLASSES["building"]) & (z > z.min() + 6.0)  # above the walls
    assert summary["segments"] >= 3  # ground and the two roof planes
    assert (np.asarray(seg["segment_id"])[roof] >= 0).mean() > 0.8
