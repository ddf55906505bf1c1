"""Pipelines in chunks (``lidarfx run --chunk-size``, ``Pipeline.run_chunked``): the cloud steps
fused per chunk give the same points as the pipeline in memory; what a chunk cannot do is refused
before any work, with the step named."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.errors import LidarfxError
from lidarfx.pipeline import Pipeline

REAL = Path(__file__).resolve().parents[2] / "shared/data/real"
IGN = REAL / "test_data_77055_627755_LA93_IGN69.laz"
IGN_WEST = REAL / "test_data_77050_627755_LA93_IGN69.laz"


def _need(*paths: Path) -> None:
    for p in paths:
        if not p.is_file():
            pytest.skip(f"real data missing: {p} (the shared IGN LiDAR HD test tiles)")


def _same_points(a_path, b_path) -> None:
    """Every point and every attribute equal, bit for bit (NaN equals NaN)."""
    a, b = lidarfx.read(a_path), lidarfx.read(b_path)
    assert len(a) == len(b)
    assert np.array_equal(a.xyz, b.xyz)
    assert sorted(a.names) == sorted(b.names)
    for n in a.names:
        x, y = np.asarray(a[n]), np.asarray(b[n])
        same = (x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == "f" else (x == y)
        assert same.all(), f"{n}: {np.count_nonzero(~same)} of {len(x)} points differ"


@pytest.fixture(scope="module")
def ign_crop(tmp_path_factory):
    """About 40 000 points of an IGN LiDAR HD tile (40 m x 40 m, buildings, vegetation, ground)."""
    _need(IGN)
    cloud = lidarfx.read(IGN)
    keep = (cloud.x < cloud.x.min() + 40) & (cloud.y < cloud.y.min() + 40)
    path = tmp_path_factory.mktemp("ign") / "crop.laz"
    lidarfx.write(cloud.subset(keep), path)
    return path


def _pipe(steps, tmp_path: Path, name: str = "p.json") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps({"pipeline": steps}))
    return p


# --------------------------------------------------------------------------- the same points as in memory
def test_ground_features_classify_in_chunks_equal_memory(ign_crop, tmp_path, run_cli):
    """read → ground (hag) → features → classify → write in 20 m chunks: every point, class,
    height and feature equals the in-memory pipeline's (the ground buffer holds the filter's reach
    on this crop), and the summary counts agree."""
    steps = [{"type": "read", "path": str(ign_crop)}, {"type": "ground", "hag": True},
             {"type": "features", "radius": [0.5, 1.0], "features": "eigen,plane"},
             {"type": "classify", "model": "default", "ground": "attribute", "min_building_area": 0,
              "confidence": True},
             {"type": "write", "path": str(tmp_path / "mem.laz")}]
    mem = Pipeline(steps)
    mem.run(progress=False)
    p = _pipe(steps, tmp_path)
    rc, out, err = run_cli(["run", str(p), "--output", str(tmp_path / "chk.laz"), "--chunk-size", "20",
                            "--workers", "1", "--json", "-q"])
    assert rc == 0, err
    s = json.loads(out)
    _same_points(tmp_path / "mem.laz", tmp_path / "chk.laz")
    assert s["chunks"]["chunks"] >= 4 and s["points"] == s["points_read"] == len(lidarfx.read(ign_crop))
    rows = {r["type"]: r for r in s["steps"]}
    assert rows["ground"]["ground_points"] == mem.summary["steps"][1]["ground_points"]
    assert rows["classify"]["classes"] == {str(c): n for c, n in mem.summary["steps"][3]["classes"].items()}  # JSON keys
    from lidarfx.classify import load_model

    assert [r["buffer_m"] for r in s["steps"]] == [100.0, 1.0, max(load_model("default").features.radii)]
    assert s["chunks"]["buffer"] == pytest.approx(sum(r["buffer_m"] for r in s["steps"]))
    assert not list(tmp_path.glob("*.lidarfx-work*"))


def test_drops_and_whole_cloud_figures_on_dask(ign_crop, tmp_path):
    """The statistical filter (its threshold from the whole input), features at two scales,
    structure classes, colour, a crop, a select and a dropping radius filter, on an embedded Dask
    cluster of two workers: the same points as in memory, bit for bit."""
    c = lidarfx.read(ign_crop)
    x0, y0 = c.xyz[:, :2].min(axis=0)
    steps = [str(ign_crop),
             {"type": "filter", "outliers": "statistical", "k": 8, "std": 2.0},
             {"type": "features", "radius": [0.5, 1.0], "features": "eigen,density"},
             {"type": "eigenclass", "radius": 1.0},
             {"type": "colour", "by": "class"},
             {"type": "crop", "bounds": [x0 + 5, y0 + 5, x0 + 33, y0 + 31]},
             {"type": "select", "where": "classification != 7 and structure != 0"},
             {"type": "filter", "outliers": "radius", "radius": 0.5, "min_neighbours": 2, "action": "drop"}]
    Pipeline(steps + [str(tmp_path / "mem.laz")]).run(progress=False)
    s = Pipeline(steps + [str(tmp_path / "chk.laz")]).run_chunked(chunk_size=12, workers=2, progress=False)
    _same_points(tmp_path / "mem.laz", tmp_path / "chk.laz")
    assert s["chunks"]["scheduler"] == "embedded LocalCluster"
    kept = [r["points"] for r in s["steps"]]
    assert kept[0] == kept[1] == kept[2] == kept[3] == len(c) > kept[4] > kept[5] >= kept[6] == s["points"]
    assert s["points"] == len(lidarfx.read(tmp_path / "chk.laz"))
    assert s["steps"][0]["threshold"] > s["steps"][0]["mean_distance"] > 0


def test_neighbourhoods_after_a_drop_equal_memory_to_rounding(ign_crop, tmp_path):
    """After a crop and a select the features are computed in the whole input's local frame (the
    in-memory pipeline: the kept points'): equal to rounding, nearly all bit for bit; a chunk whose
    square keeps no point writes nothing."""
    c = lidarfx.read(ign_crop)
    x0, y0 = c.xyz[:, :2].min(axis=0)
    steps = [str(ign_crop), {"type": "crop", "bounds": [x0 + 3.3, y0 + 1.7, x0 + 31.1, y0 + 17.9]},
             {"type": "select", "where": "z > 25"},
             {"type": "features", "radius": [0.5, 1.5], "features": "eigen,plane,density"}]
    Pipeline(steps + [str(tmp_path / "mem.laz")]).run(progress=False)
    Pipeline(steps + [str(tmp_path / "chk.laz")]).run_chunked(chunk_size=7, workers=1, progress=False)
    a, b = lidarfx.read(tmp_path / "mem.laz"), lidarfx.read(tmp_path / "chk.laz")
    assert len(a) == len(b) > 1000 and np.array_equal(a.xyz, b.xyz) and sorted(a.names) == sorted(b.names)
    differ = np.zeros(len(a), bool)
    for n in a.names:
        x, y = np.asarray(a[n], float), np.asarray(b[n], float)
        assert np.array_equal(np.isnan(x), np.isnan(y)), n
        # omnivariance is a cube root: 1e-17 of rounding in the smallest eigenvalue is 2e-6 there
        assert np.allclose(x, y, rtol=1e-6, atol=1e-5, equal_nan=True), n
        differ |= ~((x == y) | np.isnan(x))
    assert differ.mean() < 0.005


def test_folder_of_tiles_one_output_per_tile(tmp_path, run_cli):
    """A folder of two tiles → select → reproject → an output folder: one file per tile, each equal
    to the in-memory pipeline on that tile (per-point steps; coordinates within the output scale).
    The folder input switches to chunks by itself."""
    _need(IGN, IGN_WEST)
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    for src in (IGN_WEST, IGN):  # the 40 m on each side of the tiles' common border
        c = lidarfx.read(src)
        keep = (np.abs(c.x - 770_550.0) < 30) & (c.y < c.y.min() + 30)
        lidarfx.write(c.subset(keep), tiles / src.name)
    steps = [str(tiles), {"type": "select", "where": "classification == 2 or classification == 6"},
             {"type": "reproject", "to": "EPSG:4326"}, str(tmp_path / "out")]
    rc, out, err = run_cli(["run", str(_pipe(steps, tmp_path)), "--workers", "1", "-q"])
    assert rc == 0, err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted([IGN_WEST.name, IGN.name])
    for t in sorted(tiles.iterdir()):
        Pipeline([str(t), *steps[1:-1], str(tmp_path / f"mem_{t.name}")]).run(progress=False)
        a, b = lidarfx.read(tmp_path / f"mem_{t.name}"), lidarfx.read(tmp_path / "out" / t.name)
        assert len(a) == len(b) > 100
        assert np.abs(a.xyz - b.xyz).max() <= 1.01e-7  # degrees; the output scale is 1e-7
        assert np.array_equal(a["classification"], b["classification"])


def test_a_stopped_run_resumes(ign_crop, tmp_path, monkeypatch):
    """A run stopped after its first chunk keeps that chunk; resumed, it computes the others only
    and gives the same file as a run in one go."""
    from lidarfx.tiles import engine

    steps = [str(ign_crop), {"type": "features", "radius": 1.0, "features": "eigen"},
             {"type": "select", "where": "linearity > 0.5"}]
    Pipeline(steps + [str(tmp_path / "once.laz")]).run_chunked(chunk_size=20, workers=1, progress=False)
    real, calls = engine.process_chunk, []

    def stop_second(work, name, spec):
        calls.append(name)
        if len(calls) == 2:
            raise KeyboardInterrupt  # as a user's Ctrl-C
        return real(work, name, spec)

    monkeypatch.setattr(engine, "process_chunk", stop_second)
    pipe = Pipeline(steps + [str(tmp_path / "out.laz")])
    with pytest.raises(KeyboardInterrupt):
        pipe.run_chunked(chunk_size=20, workers=1, progress=False)
    assert not (tmp_path / "out.laz").exists() and (tmp_path / "out.laz.lidarfx-work").is_dir()
    monkeypatch.setattr(engine, "process_chunk", real)
    s = pipe.run_chunked(chunk_size=20, workers=1, progress=False, resume=True)
    assert s["chunks"]["chunks_resumed"] == 1 and s["chunks"]["chunks"] >= 4
    _same_points(tmp_path / "once.laz", tmp_path / "out.laz")


def test_an_empty_result(ign_crop, tmp_path, run_cli):
    """No point left: an error naming the crop step and nothing written, or with allow_empty an
    empty file."""
    far = [0, 0, 1, 1]
    steps = [str(ign_crop), {"type": "crop", "bounds": far}, str(tmp_path / "e.laz")]
    rc, out, err = run_cli(["run", str(_pipe(steps, tmp_path)), "--chunk-size", "20", "--workers", "1", "-q"])
    assert rc == 2 and "step 2 (crop): no point is left" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "e.laz").exists()
    steps[1]["allow_empty"] = True
    rc, out, err = run_cli(["run", str(_pipe(steps, tmp_path)), "--chunk-size", "20", "--workers", "1", "-q"])
    assert rc == 0, err
    assert len(lidarfx.read(tmp_path / "e.laz")) == 0


# --------------------------------------------------------------------------- refused before any work
REFUSED = [
    ([{"type": "dtm", "output": "d.tif"}], "step 2 (dtm) writes a product of the whole cloud"),
    ([{"type": "thin", "cell": 1.0}], "step 2 (thin) keeps one point per cell"),
    ([{"type": "segment"}], "step 2 (segment) grows planes"),
    ([{"type": "ground", "dtm": "d.tif"}], "step 2 (ground): the DTM is made from the whole cloud"),
    ([{"type": "features", "radius": 1, "picture": "f.png"}], None),
    ([{"type": "eigenclass", "radius": 1.0, "picture": "e.png"}], "step 2 (eigenclass): the picture draws"),
    ([{"type": "reproject", "to": "EPSG:4326"}, {"type": "select", "where": "z > 0"}],
     "step 3 (select) comes after step 2 (reproject)"),
    ([{"type": "select", "where": "z > 0"}, {"type": "classify", "model": "default"}],
     "step 3 (classify) takes the usable points and their density from the input, but step 2 drops"),
    ([{"type": "crop", "bounds": [0, 0, 1, 1]}, {"type": "filter", "outliers": "statistical"}],
     "step 3 (filter) takes the mean neighbour distance"),
    ([{"type": "ground", "hag": True}, {"type": "colour", "by": "height_above_ground"}],
     'step 3 (colour) takes the 2-98 % range of height_above_ground from the input, but step 2 writes'),
    ([{"type": "write", "path": "mid.laz"}], "one write step, the last"),
    ([{"type": "features", "radius": 1, "features": "normal_x,normal_y,normal_z"}, {"type": "colour", "by": "morphology"}],
     "step 3 (colour) by morphology after step 2 (features), which computes normals"),
    ([{"type": "eigenclass"}], "step 2 (eigenclass): in chunks: in chunks, give the radius"),
    ([{"type": "classify", "model": "default"}], "step 2 (classify): in chunks: the small-building rule"),
]


@pytest.mark.parametrize("middle,message", REFUSED, ids=[str(i) for i in range(len(REFUSED))])
def test_refused_before_any_work(ign_crop, tmp_path, run_cli, middle, message):
    steps = [str(ign_crop), *middle, str(tmp_path / "out.laz")]
    p = _pipe(steps, tmp_path)
    before = {q.name for q in tmp_path.iterdir()}
    rc, out, err = run_cli(["run", str(p), "--chunk-size", "20", "--workers", "1", "-q"])
    if message is None:  # a key the step does not have, or a value its check refuses: refused as in memory
        assert rc == 2 and "lidarfx: error:" in err
    else:
        assert rc == 2 and message in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert {q.name for q in tmp_path.iterdir()} == before  # nothing written, no work folder


def test_colour_by_a_computed_attribute_with_a_range(ign_crop, tmp_path):
    """colour by an attribute an earlier step writes runs in chunks with a given range, and gives
    the in-memory colours."""
    steps = [str(ign_crop), {"type": "ground", "hag": True},
             {"type": "colour", "by": "height_above_ground", "range": [0, 20], "cmap": "magma"}]
    Pipeline(steps + [str(tmp_path / "mem.laz")]).run(progress=False)
    Pipeline(steps + [str(tmp_path / "chk.laz")]).run_chunked(chunk_size=20, workers=1, progress=False)
    _same_points(tmp_path / "mem.laz", tmp_path / "chk.laz")
    with pytest.raises(LidarfxError, match='step 3 \\(colour\\).*"range"'):
        Pipeline(steps[:2] + [{"type": "colour", "by": "height_above_ground"}, str(tmp_path / "x.laz")]) \
            .run_chunked(chunk_size=20, workers=1)


def test_buffer_narrower_than_the_exact_steps(ign_crop, tmp_path, run_cli):
    steps = [str(ign_crop), {"type": "features", "radius": 2.0, "features": "eigen"},
             {"type": "eigenclass", "radius": 1.5}, str(tmp_path / "o.laz")]
    rc, out, err = run_cli(["run", str(_pipe(steps, tmp_path)), "--buffer", "3", "--workers", "1", "-q"])
    assert rc == 2 and "narrower than the 3.5 m" in err, err
    assert not (tmp_path / "o.laz").exists()


def test_dry_run_in_chunks_and_overwrite(ign_crop, tmp_path, run_cli):
    out = tmp_path / "o.laz"
    steps = [str(ign_crop), {"type": "select", "where": "z > 0"}, str(out)]
    p = _pipe(steps, tmp_path)
    rc, text, err = run_cli(["run", str(p), "--chunk-size", "20", "--dry-run"])
    assert rc == 0 and "valid in chunks" in text and not out.exists()
    rc, text, err = run_cli(["run", str(p), "--chunk-size", "20", "--dry-run"])
    out.write_bytes(b"old")
    rc, text, err = run_cli(["run", str(p), "--chunk-size", "20", "--workers", "1", "-q"])
    assert rc == 2 and "--force" in err and out.read_bytes() == b"old"
    rc, text, err = run_cli(["--force", "run", str(p), "--chunk-size", "20", "--workers", "1", "-q"])
    assert rc == 0 and len(lidarfx.read(out)) == len(lidarfx.read(ign_crop))


def test_in_memory_pipelines_are_unchanged_by_default(ign_crop, tmp_path, run_cli):
    """Without a chunk option a pipeline with a product step runs in memory as before."""
    steps = [str(ign_crop), {"type": "ground"}, {"type": "dtm", "output": str(tmp_path / "d.asc"), "resolution": 2},
             str(tmp_path / "g.laz")]
    rc, out, err = run_cli(["run", str(_pipe(steps, tmp_path)), "-q", "--json"])
    assert rc == 0, err
    assert "chunks" not in json.loads(out) and (tmp_path / "d.asc").is_file()


def test_a_failing_chunk_on_dask_is_one_line(tmp_path):
    """A chunk that fails on the workers of an embedded cluster: the run's one line on stderr, not
    the workers' logs and tracebacks (nor a warning about a busy dashboard port)."""
    import subprocess
    import sys

    src = REAL / "samp11-utm.laz"
    _need(src)
    res = subprocess.run([sys.executable, "-m", "lidarfx", "features", str(src), str(tmp_path / "k.laz"),
                          "--neighbourhood", "knn", "-k", "30", "-f", "eigen", "--buffer", "0.01", "--chunk-size", "100",
                          "--workers", "2", "-q"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("lidarfx: error: chunk c"), res.stderr
    assert "give --buffer" in res.stderr
    assert list(tmp_path.iterdir()) == []  # no output, and no work folder: other options cannot resume it
