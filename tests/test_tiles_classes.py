"""lidarfx eigenclass and lidarfx classify predict in chunks: every point's values equal the
in-memory run's, bit for bit, points on chunk borders included."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

import lidarfx
from lidarfx import io
from lidarfx.cli import main

CHUNK = 10.0


def _scene(withheld: bool = False) -> lidarfx.PointCloud:
    """A grid-sampled house on flat ground in map coordinates (about 48 m × 48 m, 21 000 points,
    so 25 chunks of 10 m) with the points within 0.3 m of a chunk border moved onto it (x or y a multiple of
    10 m, corners too) and a height above ground."""
    c = lidarfx.synth.house(sampling="grid", density=16, margin=12, seed=1, origin=(652_300.0, 6_862_100.0, 40.0))
    xyz = c.xyz.copy()
    for a in (0, 1):
        snap = np.round(xyz[:, a] / CHUNK) * CHUNK
        near = np.abs(xyz[:, a] - snap) < 0.3
        xyz[near, a] = snap[near]
    out = lidarfx.PointCloud(xyz, {"classification": np.asarray(c["classification"])})
    out["height_above_ground"] = np.maximum(xyz[:, 2] - 40.0, 0.0).astype(np.float32)
    if withheld:  # 5 % withheld: neither neighbours nor classified, their class kept
        out["withheld"] = np.random.default_rng(3).random(len(out)) < 0.05
        out["classification"] = np.where(out["withheld"], 7, out["classification"]).astype(np.uint8)
    return out


def _write(path, cloud):
    io.write(cloud, path, progress=False)
    back = io.read(path, progress=False)
    on_border = (back.x % CHUNK == 0) | (back.y % CHUNK == 0)
    assert on_border.sum() > 1000  # points exactly on chunk borders survive the LAS scale
    return path


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return _write(tmp_path_factory.mktemp("scene") / "house.las", _scene())


@pytest.fixture(scope="module")
def withheld_scene(tmp_path_factory):
    return _write(tmp_path_factory.mktemp("scene_withheld") / "house.las", _scene(withheld=True))


def _same(a_path, b_path, names):
    a, b = io.read(a_path, progress=False), io.read(b_path, progress=False)
    assert len(a) == len(b)
    assert np.array_equal(a.xyz, b.xyz)
    for n in names:
        assert n in a and n in b, n
        va, vb = np.asarray(a[n]), np.asarray(b[n])
        assert va.dtype == vb.dtype, n
        assert np.array_equal(va, vb, equal_nan=va.dtype.kind == "f"), n
    return a


def test_eigenclass_chunks_equal_one_run(scene, tmp_path, capsys):
    one = tmp_path / "one.las"
    out = tmp_path / "chunks"
    args = [str(scene), "-r", "1", "-r", "1.5", "--keep-signature", "-q"]
    assert main(["eigenclass", args[0], str(one), *args[1:], "--chunk-size", "0"]) == 0
    capsys.readouterr()
    assert main(["eigenclass", args[0], str(out), *args[1:], "--chunk-size", str(CHUNK), "--workers", "1",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chunks"] >= 16 and summary["buffer"] == 1.5
    names = ["structure", "structure_confidence", "structure_distance"] + [
        f"{s}_r{r}" for r in ("1.00", "1.50") for s in ("e1", "e2", "e3", "centroid_offset", "n_neighbours")]
    a = _same(one, out / scene.name, names)
    assert len(np.unique(np.asarray(a["structure"]))) >= 3  # planes, borders, edges ...


def _fails(argv, capsys, pattern):
    assert main(argv) != 0
    err = capsys.readouterr().err
    assert re.search(pattern, err), err
    assert len(err.strip().splitlines()) == 1


def test_eigenclass_chunks_need_a_radius(scene, tmp_path, capsys):
    _fails(["eigenclass", str(scene), str(tmp_path / "o"), "--chunk-size", "10", "-q"], capsys,
           r"give the radius: -r R.*about -r 1\.2 holds 40 points")


def _train(path, thin):
    from lidarfx.classify import train

    m = train(_scene(), classes="2,6", features="eigen,plane,echo_ratio_slope,height_above_ground", radii=[1.0, 2.0],
              ground="attribute", max_disc_points=thin, terrain_augment=0, max_per_class=2000, n_estimators=20)
    m.save(path)
    return path


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    """Thins the neighbour cloud (20 points per 1 m disc ≈ 6.4 pts/m², the scene has 14.6 over its
    occupied squares): the draws of a chunk's points must be the whole cloud's."""
    return _train(tmp_path_factory.mktemp("model") / "m.skops", 20)


@pytest.fixture(scope="module")
def model_no_thin(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("model") / "m.skops", None)


def _predict_both(scene, model, tmp_path):
    one = tmp_path / "one.las"
    out = tmp_path / "chunks"
    common = ["--model", str(model), "--ground", "attribute", "--min-building-area", "0", "--confidence",
              "--probabilities", "-q"]
    assert main(["classify", "predict", str(scene), str(one), *common, "--chunk-size", "0"]) == 0
    assert main(["classify", "predict", str(scene), str(out), *common, "--chunk-size", str(CHUNK),
                 "--workers", "1"]) == 0
    a = _same(one, out / scene.name, ["classification", "confidence", "probability_ground", "probability_building"])
    cls = np.asarray(a["classification"])
    held = np.asarray(a["withheld"]).astype(bool)
    assert set(np.unique(cls[~held])) == {2, 6} and np.all(cls[held] == 7)  # withheld points keep their class


def test_classify_predict_chunks_equal_one_run(scene, model, tmp_path):
    _predict_both(scene, model, tmp_path)


def test_classify_predict_chunks_with_withheld_points(withheld_scene, model_no_thin, tmp_path):
    """Withheld points are neither neighbours nor classified: the index origin is the usable points'
    minimum, computed before the run."""
    _predict_both(withheld_scene, model_no_thin, tmp_path)


def test_classify_predict_chunks_refuse_thinning_over_unusable_points(withheld_scene, model, tmp_path, capsys):
    _fails(["classify", "predict", str(withheld_scene), str(tmp_path / "o"), "--model", str(model), "--chunk-size",
            "10", "-q", "--ground", "attribute", "--min-building-area", "0"], capsys,
           "thins clouds denser than .* virtual, withheld or synthetic points")


def test_classify_predict_chunks_refuse_what_is_not_local(scene, model, tmp_path, capsys):
    base = ["classify", "predict", str(scene), str(tmp_path / "o"), "--model", str(model), "--chunk-size", "10", "-q"]
    _fails(base + ["--ground", "smrf", "--min-building-area", "0"], capsys, "ground filter, which is not local")
    _fails(base + ["--ground", "attribute", "--min-building-area", "5"], capsys, "give --min-building-area 0 in chunks")
    _fails(base + ["--ground", "attribute", "--min-building-area", "0", "--picture", str(tmp_path / "p.png")], capsys,
           "--picture draws the whole cloud")
