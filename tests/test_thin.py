"""Block thinning: one point per occupied cell, the kept point of every mode against a brute-force
reference, streaming = in memory, records and header passed through, the CLI."""
from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx import PointCloud
from lidarfx.errors import LidarfxError
from lidarfx.thin import KEEP, thin_cloud, thin_file, thin_indices

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
UTM33_WKT = ('PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
             'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],'
             'PARAMETER["central_meridian",15],PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
             'UNIT["metre",1],AUTHORITY["EPSG","32633"]]')


def _cloud(seed=0, n=4000, offset=(0.0, 0.0, 0.0)):
    """Points in a 1 m cube, some duplicates, some exactly on cell faces of 0.1 (lattice points)."""
    rng = np.random.default_rng(seed)
    xyz = np.round(rng.uniform(0.0, 1.0, (n, 3)), 3)  # mm steps: many points on faces of a 0.1 grid
    xyz[: n // 10] = xyz[n // 10: 2 * (n // 10)]  # exact duplicates: ties in every mode
    return xyz + np.asarray(offset)


def _reference(xyz, cell, keep):
    """Brute force: a dict from cell to the best (score, index), in plain Python."""
    best = {}
    for i, (x, y, z) in enumerate(xyz.tolist()):
        c = (math.floor(x / cell), math.floor(y / cell), math.floor(z / cell))
        if keep == "centre":
            score = sum((v - (k + 0.5) * cell) ** 2 for v, k in zip((x, y, z), c))
        elif keep == "first":
            score = 0.0
        elif keep == "lowest":
            score = z
        elif keep == "highest":
            score = -z
        else:
            raise ValueError(keep)
        if c not in best or (score, i) < best[c]:
            best[c] = (score, i)
    return sorted(i for _, i in best.values())


def _cells(xyz, cell):
    return {tuple(c) for c in np.floor(xyz / cell).astype(np.int64).tolist()}


@pytest.mark.parametrize("keep", ["centre", "first", "lowest", "highest"])
def test_kept_point_is_the_brute_force_one(keep):
    xyz = _cloud(1)
    got = thin_indices(xyz, 0.1, keep)
    assert got.tolist() == _reference(xyz, 0.1, keep)
    assert thin_indices(xyz, 0.1, keep, chunk_points=37).tolist() == got.tolist()  # any chunking


def test_utm_sized_coordinates_and_negative_ones():
    for off in ((500_000.0, 5_000_000.0, 300.0), (-123.4, -77.0, -5.0)):
        xyz = _cloud(2, offset=off)
        for keep in ("centre", "lowest"):
            assert thin_indices(xyz, 0.1, keep).tolist() == _reference(xyz, 0.1, keep)


@pytest.mark.parametrize("keep", KEEP)
def test_one_point_per_occupied_cell(keep):
    xyz = _cloud(3)
    idx = thin_indices(xyz, 0.1, keep, seed=5)
    kept = np.floor(xyz[idx] / 0.1).astype(np.int64)
    assert len({tuple(c) for c in kept.tolist()}) == len(idx)  # all distinct
    assert _cells(xyz[idx], 0.1) == _cells(xyz, 0.1)  # the same occupied cells
    assert np.all(np.diff(idx) > 0)  # file order


def test_random_is_seeded_uniform_and_chunking_free():
    # 2000 cells of exactly 4 points each: which of the 4 is kept should be uniform
    rng = np.random.default_rng(4)
    centres = (np.arange(2000)[:, None] * np.array([1.0, 0.0, 0.0])) + 0.5
    xyz = np.repeat(centres, 4, axis=0) + rng.uniform(-0.4, 0.4, (8000, 3))
    a = thin_indices(xyz, 1.0, "random", seed=11)
    assert len(a) == 2000
    assert thin_indices(xyz, 1.0, "random", seed=11, chunk_points=3).tolist() == a.tolist()
    b = thin_indices(xyz, 1.0, "random", seed=12)
    assert (a != b).mean() > 0.6  # another seed, another choice (3/4 expected)
    counts = np.bincount(a % 4, minlength=4)
    assert counts.min() > 400 and counts.max() < 600  # 500 each expected (sd 19)


def test_errors():
    xyz = _cloud(0, n=100)
    for bad in (0, -1, math.nan, math.inf, "0.1", True):
        with pytest.raises(LidarfxError, match="cell must be a number"):
            thin_indices(xyz, bad)
    with pytest.raises(LidarfxError, match="keep must be one of"):
        thin_indices(xyz, 0.1, "middle")
    assert thin_indices(xyz, 0.1, "center").tolist() == thin_indices(xyz, 0.1, "centre").tolist()
    big = np.array([[0.0, 0.0, 0.0], [1e6, 1e6, 1e3]])
    with pytest.raises(LidarfxError, match="the cell is too small for the cloud's extent: the thinning grid"):
        thin_indices(big, 1e-6)
    with pytest.raises(LidarfxError, match="too small for the coordinates"):
        thin_indices(np.array([[1e300, 0.0, 0.0]]), 1e-9)
    with pytest.raises(LidarfxError, match="NaN"):
        thin_indices(np.array([[0.0, np.nan, 0.0]]), 0.1)
    assert thin_indices(np.zeros((0, 3)), 0.1).tolist() == []
    assert thin_cloud(PointCloud(xyz), 0.1).tolist() == thin_indices(xyz, 0.1).tolist()


def _las_file(path, xyz, seed=0, version="1.4", point_format=6):
    """A LAS/LAZ file with every kind of attribute: classes, intensity, gps time, an extra dimension, a CRS."""
    rng = np.random.default_rng(seed)
    h = laspy.LasHeader(point_format=point_format, version=version)
    h.scales, h.offsets = [0.001] * 3, np.floor(xyz.min(axis=0))
    h.add_extra_dim(laspy.ExtraBytesParams(name="reflectance", type=np.float32, description="test"))
    h.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(UTM33_WKT))
    las = laspy.LasData(h)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    n = len(xyz)
    las.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    las.classification = rng.integers(0, 20, n).astype(np.uint8)
    las.gps_time = rng.uniform(0, 1e5, n)
    las.return_number = np.ones(n, np.uint8)
    las.number_of_returns = np.ones(n, np.uint8)
    las.reflectance = rng.normal(0, 1, n).astype(np.float32)
    las.write(path)
    return path


@pytest.mark.parametrize("ext", [".las", ".laz"])
@pytest.mark.parametrize("keep", KEEP)
def test_streaming_equals_in_memory_and_records_pass_through(tmp_path, ext, keep):
    xyz = _cloud(5, n=3000, offset=(500_000.0, 5_000_000.0, 300.0))
    src = _las_file(tmp_path / f"in{ext}", xyz)
    before = src.read_bytes()
    out = tmp_path / f"out{ext}"
    s = thin_file(src, out, cell=0.1, keep=keep, seed=3, chunk_points=7)  # tiny chunks
    assert src.read_bytes() == before  # the input is never modified
    full = lidarfx.read(src)
    idx = thin_cloud(full, 0.1, keep, seed=3)
    assert s["kept"] == len(idx) and s["points"] == 3000 and s["mode"] == "streamed"
    a, b = laspy.read(src), laspy.read(out)
    assert np.array_equal(b.points.array, a.points.array[idx])  # the kept records, bit for bit
    assert b.header.point_format == a.header.point_format and str(b.header.version) == str(a.header.version)
    assert np.array_equal(b.header.scales, a.header.scales) and np.array_equal(b.header.offsets, a.header.offsets)
    assert [type(v).__name__ for v in b.header.vlrs] == [type(v).__name__ for v in a.header.vlrs]
    assert lidarfx.io.info(out)["crs"] == lidarfx.io.info(src)["crs"]
    assert np.allclose(b.header.mins, b.xyz.min(axis=0)) and np.allclose(b.header.maxs, b.xyz.max(axis=0))
    if keep != "random":
        assert idx.tolist() == _reference(full.xyz, 0.1, keep)


@pytest.mark.parametrize("budget", [0, 3000, 1 << 30])  # records read again / dropped midway / kept in pass 1
def test_one_or_two_passes_give_the_same_file(tmp_path, budget):
    xyz = _cloud(9, n=3000, offset=(500_000.0, 5_000_000.0, 300.0))
    src = _las_file(tmp_path / "in.laz", xyz)
    s = thin_file(src, tmp_path / "out.laz", cell=0.1, keep="random", chunk_points=100, record_budget=budget)
    assert s["passes"] == (1 if budget > 1e6 else 2)
    idx = thin_cloud(lidarfx.read(src), 0.1, "random")
    assert np.array_equal(laspy.read(tmp_path / "out.laz").points.array, laspy.read(src).points.array[idx])
    s = thin_file(src, tmp_path / "out.ply", cell=0.1, keep="random", chunk_points=100, record_budget=budget)
    assert np.array_equal(lidarfx.read(tmp_path / "out.ply")["gps_time"], lidarfx.read(src)["gps_time"][idx])


def test_other_formats_in_and_out(tmp_path):
    xyz = _cloud(6, n=2000)
    src = _las_file(tmp_path / "in.laz", xyz)
    s = thin_file(src, tmp_path / "out.npz", cell=0.1, chunk_points=100)  # streamed in, in memory out
    full = lidarfx.read(src)
    idx = thin_cloud(full, 0.1)
    got = lidarfx.read(tmp_path / "out.npz")
    assert s["kept"] == len(idx) and np.allclose(got.xyz, full.xyz[idx])
    assert np.array_equal(got["reflectance"], full["reflectance"][idx])
    s = thin_file(tmp_path / "out.npz", tmp_path / "again.ply", cell=0.2)  # in memory
    assert s["mode"] == "in memory"
    assert lidarfx.read(tmp_path / "again.ply").xyz.tolist() == got.xyz[thin_cloud(got, 0.2)].tolist()


def test_stale_header_bounds_are_scanned(tmp_path):
    xyz = _cloud(7, n=2000)
    src = _las_file(tmp_path / "in.las", xyz, version="1.2", point_format=3)
    raw = bytearray(src.read_bytes())
    # LAS header: max x, min x, max y, min y, max z, min z as doubles from byte 179
    struct.pack_into("<6d", raw, 179, 0.5, 0.4, 0.5, 0.4, 0.5, 0.4)
    src.write_bytes(bytes(raw))
    s = thin_file(src, tmp_path / "out.las", cell=0.1, chunk_points=64)
    assert s["bounds"].startswith("scanned")
    idx = thin_indices(lidarfx.read(src).xyz, 0.1)
    assert laspy.read(tmp_path / "out.las").points.array.tolist() == laspy.read(src).points.array[idx].tolist()


def test_empty_file(tmp_path):
    h = laspy.LasHeader(point_format=6, version="1.4")
    laspy.LasData(h).write(tmp_path / "e.laz")
    s = thin_file(tmp_path / "e.laz", tmp_path / "o.laz", cell=0.1)
    assert s["points"] == 0 and s["kept"] == 0 and len(laspy.read(tmp_path / "o.laz").points) == 0
    assert thin_file(tmp_path / "e.laz", tmp_path / "o.ply", cell=0.1)["kept"] == 0


# ----------------------------------------------------------------------------- CLI
def test_cli_json_and_quiet(tmp_path, run_cli):
    xyz = _cloud(8, n=2000)
    src = _las_file(tmp_path / "in.laz", xyz)
    rc, out, err = run_cli(["thin", str(src), str(tmp_path / "o.laz"), "--cell", "0.1", "--keep", "lowest", "--json"])
    assert rc == 0, err
    s = json.loads(out)
    assert s["kept"] == len(_reference(lidarfx.read(src).xyz, 0.1, "lowest")) and s["keep"] == "lowest"
    rc, out, err = run_cli(["thin", str(src), str(tmp_path / "o2.laz"), "--cell", "0.1", "-q"])
    assert rc == 0 and out == "" and err == ""


def test_cli_help_has_examples(run_cli):
    rc, out, _ = run_cli(["thin", "--help"])
    assert rc == 0 and "examples:" in out and "--keep" in out


def _one_line_error(rc, err, match):
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("lidarfx")]
    assert rc == 2 and lines and match in lines[-1], err
    assert "Traceback" not in err


@pytest.mark.parametrize("cell", ["0", "-1", "nan", "inf"])
def test_cli_bad_cell(tmp_path, run_cli, cell):
    src = _las_file(tmp_path / "in.laz", _cloud(0, n=50))
    rc, _, err = run_cli(["thin", str(src), str(tmp_path / "o.laz"), "--cell", cell])
    _one_line_error(rc, err, "cell must be a number")
    assert not (tmp_path / "o.laz").exists()


def test_cli_bad_files(tmp_path, run_cli):
    src = _las_file(tmp_path / "in.laz", _cloud(0, n=3000))
    rc, _, err = run_cli(["thin", str(tmp_path / "missing.laz"), str(tmp_path / "o.laz"), "--cell", "0.1"])
    _one_line_error(rc, err, "file not found")
    rc, _, err = run_cli(["thin", str(src), str(src), "--cell", "0.1"])
    _one_line_error(rc, err, "is the input file")
    rc, _, err = run_cli(["thin", str(src), str(tmp_path / "o.xyzw"), "--cell", "0.1"])
    _one_line_error(rc, err, "unknown file extension")
    rc, _, err = run_cli(["thin", str(src), str(tmp_path / "nofolder" / "o.laz"), "--cell", "0.1"])
    _one_line_error(rc, err, "output folder does not exist")
    rc, _, err = run_cli(["thin", str(src), str(tmp_path / "o.laz"), "--cell", "0.1", "--seed", "-1"])
    _one_line_error(rc, err, "seed must be an integer")
    data = src.read_bytes()
    (tmp_path / "trunc.laz").write_bytes(data[: len(data) // 2])
    (tmp_path / "garbage.laz").write_bytes(np.random.default_rng(0).bytes(3000))
    for bad in ("trunc.laz", "garbage.laz"):
        rc, _, err = run_cli(["thin", str(tmp_path / bad), str(tmp_path / "o.laz"), "--cell", "0.1"])
        _one_line_error(rc, err, bad)
        assert not (tmp_path / "o.laz").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left behind


@pytest.mark.skipif(not (REAL / "lone-star.laz").exists(), reason=f"real TLS scan not found: {REAL / 'lone-star.laz'}")
def test_real_tls_scan(tmp_path):
    src = REAL / "lone-star.laz"
    s = thin_file(src, tmp_path / "t.laz", cell=0.05, chunk_points=100_000)
    idx = thin_cloud(lidarfx.read(src), 0.05)
    a, b = laspy.read(src), laspy.read(tmp_path / "t.laz")
    assert s["kept"] == len(idx) == len(b.points) and np.array_equal(b.points.array, a.points.array[idx])
    assert lidarfx.io.info(tmp_path / "t.laz")["crs"] == lidarfx.io.info(src)["crs"]
    assert str(b.header.version) == "1.1" and b.header.point_format.id == 1
