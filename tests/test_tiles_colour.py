"""``lidarfx colour`` in chunks equals the in-memory run for every point; ``lidarfx segment`` refuses a folder."""
from __future__ import annotations

import numpy as np
import pytest

import lidarfx
from lidarfx import synth
from lidarfx.cli import main
from lidarfx.errors import LidarfxError
from lidarfx.tiles import proc_colour
from lidarfx.tiles.proc_colour import colour_options, exact_percentiles

RGB = ("red", "green", "blue")
CHUNKED = ["--chunk-size", "10", "--workers", "1", "-q"]


@pytest.fixture(scope="module")
def house_las(tmp_path_factory):
    """An ALS house (about 10 000 points over 42 × 43 m, chunk borders through the roof) with
    an attribute holding NaN and normals of its own in a second file."""
    d = tmp_path_factory.mktemp("house")
    cloud = synth.house(density=10.0, wall_density=2.0, seed=3)
    cloud = lidarfx.PointCloud(cloud.xyz + [500.0, 700.0, 40.0], {"classification": cloud["classification"]})
    feat = (cloud.z - 40.0).astype(np.float32)
    feat[::17] = np.nan
    cloud["feat"] = feat
    path = d / "house.las"
    lidarfx.write(cloud, path)
    with_normals = cloud.copy()
    rng = np.random.default_rng(0)
    n = rng.normal(size=(len(cloud), 3)).astype(np.float32)
    n[::23] = 0.0
    for k, name in enumerate(("normal_x", "normal_y", "normal_z")):
        with_normals[name] = n[:, k]
    npath = d / "normals.las"
    lidarfx.write(with_normals, npath)
    return path, npath


def in_memory(src, tmp_path, *extra) -> lidarfx.PointCloud:
    ref = tmp_path / "ref.las"
    assert main(["colour", str(src), str(ref), *extra, "--chunk-size", "0", "-q"]) == 0
    return lidarfx.read(ref)


def chunked(src, tmp_path, *extra) -> lidarfx.PointCloud:
    out = tmp_path / "chunks"
    assert main(["colour", str(src), str(out), *extra, *CHUNKED]) == 0
    assert not (tmp_path / "chunks.lidarfx-work").exists()
    return lidarfx.read(out / src.name)


def assert_same_colours(a, b) -> None:
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    for name in RGB:
        assert b[name].dtype == np.uint16
        np.testing.assert_array_equal(a[name], b[name])


@pytest.mark.parametrize("extra", [
    ["-r", "1.5", "--sun-azimuth", "200"],  # normals computed: buffer = radius
    ["--by", "z"],  # exact 2-98 % range of the whole input
    ["--by", "feat", "--cmap", "magma"],  # NaN grey, range over the finite values
    ["--by", "z", "--range", "35,50"],
    ["--by", "class"],
], ids=["morphology", "z", "feat-nan", "range", "class"])
def test_chunks_equal_in_memory(house_las, tmp_path, extra):
    src, _ = house_las
    ref = in_memory(src, tmp_path, *extra)
    got = chunked(src, tmp_path, *extra)
    assert_same_colours(ref, got)
    assert len(np.unique(np.column_stack([got[k] for k in RGB]), axis=0)) > 1


def test_normals_of_the_input_need_no_radius(house_las, tmp_path):
    _, npath = house_las
    assert colour_options(npath)["normals"] == "attributes"
    assert_same_colours(in_memory(npath, tmp_path), chunked(npath, tmp_path))


def test_percentiles_by_radix_selection_equal_in_memory(house_las, tmp_path, monkeypatch):
    """Inputs larger than the values kept in memory: the range by streaming radix selection."""
    src, _ = house_las
    ref = in_memory(src, tmp_path, "--by", "feat")
    monkeypatch.setattr(proc_colour, "IN_MEMORY_VALUES", 50)
    o = colour_options(src, "feat")
    f = lidarfx.read(src)["feat"].astype(np.float64)
    assert o["range"] == [float(v) for v in np.percentile(f[np.isfinite(f)], [2, 98])]
    assert_same_colours(ref, chunked(src, tmp_path, "--by", "feat"))


def test_a_folder_of_tiles_equals_the_whole(house_las, tmp_path):
    """Two tiles: their percentiles are the whole input's, each tile's colours the whole's."""
    src, _ = house_las
    whole = lidarfx.read(src)
    west = whole.x < 500.0
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    lidarfx.write(whole.subset(west), tiles / "a.las")
    lidarfx.write(whole.subset(~west), tiles / "b.las")
    ref = in_memory(src, tmp_path, "--by", "z")
    out = tmp_path / "out"
    assert main(["colour", str(tiles), str(out), "--by", "z", *CHUNKED]) == 0
    for name, part in (("a.las", west), ("b.las", ~west)):
        assert_same_colours(ref.subset(part), lidarfx.read(out / name))


def test_exact_percentiles_match_numpy():
    rng = np.random.default_rng(1)
    for t in range(120):
        n = int(rng.integers(1, 2000))
        v = [rng.normal(size=n) * 10.0 ** int(rng.integers(-4, 5)), rng.integers(-5, 5, n).astype(float),
             np.round(rng.uniform(-100, 100, n), 2)][t % 3]
        v[rng.random(n) < 0.05] = np.nan
        parts = np.array_split(v, 1 + t % 4)
        f = v[np.isfinite(v)]
        count, got = exact_percentiles(lambda: iter(parts), in_memory=int(rng.integers(0, 40)))
        assert count == len(f)
        if len(f):
            assert got == [float(p) for p in np.percentile(f, [2, 98])]
    assert exact_percentiles(lambda: iter([np.array([np.nan])])) == (0, [])


@pytest.mark.parametrize("extra, match", [
    ([], "needs --radius"),
    (["-r", "1", "--picture", "x.png"], "--picture draws every point"),
    (["--by", "nope"], "no attribute 'nope'"),
    (["--by", "set"], "needs the set_id attribute"),
])
def test_chunked_errors(house_las, tmp_path, capsys, extra, match, monkeypatch):
    src, _ = house_las
    monkeypatch.chdir(tmp_path)
    assert main(["colour", str(src), str(tmp_path / "o"), *extra, *CHUNKED]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1


def test_run_tiled_checks_colour_options(house_las, tmp_path):
    from lidarfx.tiles import run_tiled

    src, _ = house_las
    with pytest.raises(LidarfxError, match="value range of the whole input"):
        run_tiled(src, tmp_path / "o", "colour", {"by": "z"}, chunk_size=10, workers=1)
    with pytest.raises(LidarfxError, match="needs --radius"):
        run_tiled(src, tmp_path / "o", "colour", {"by": "morphology", "normals": "computed"}, chunk_size=10, workers=1)


# --------------------------------------------------------------------------- segment
def test_segment_refuses_a_folder(house_las, tmp_path, capsys):
    src, _ = house_las
    assert main(["segment", str(src.parent), str(tmp_path / "seg"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "not local" in err and err.count("\n") == 1 and not (tmp_path / "seg").exists()
    from lidarfx.tiles import run_tiled

    with pytest.raises(LidarfxError, match="segment does not run in chunks"):
        run_tiled(src, tmp_path / "o", "segment", {}, chunk_size=10, workers=1)
