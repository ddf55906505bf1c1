"""Chunked runs (lidarfx.tiles): the grid, the split, features equal to the in-memory run bit
for bit (points on chunk borders included), several inputs, kNN buffers, a Dask cluster,
resume after a killed run, retries, and bad input."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx.errors import LidarfxError
from lidarfx.tiles.engine import execute
from lidarfx.tiles.plan import Grid, chunk_name, default_chunk_size

FEATURES = "eigen,plane,density,msac"


def _write(path: Path, xyz: np.ndarray, gps: np.ndarray) -> None:
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([500_000.0, 5_000_000.0, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.gps_time = gps
    las.classification = np.full(len(xyz), 2, np.uint8)
    las.write(str(path))


def lattice(nx: int = 80, ny: int = 60, step: float = 0.25, seed: int = 0) -> np.ndarray:
    """Points on a 0.25 m lattice (many exactly on chunk borders at multiples of 5 m), a roof
    ridge and noise in z, at UTM-sized coordinates."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(nx) * step, np.arange(ny) * step, indexing="ij")
    x, y = gx.ravel() + 500_100.0, gy.ravel() + 5_000_200.0
    z = 300.0 + 0.3 * np.abs(gy.ravel() - 7.3) + 0.1 * np.sin(gx.ravel()) + rng.normal(0, 0.01, x.size)
    return np.column_stack([x, y, z])


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiles")
    xyz = lattice()
    src = d / "scene.las"
    _write(src, xyz, np.arange(len(xyz), dtype=np.float64))
    return d, src, xyz


def _equal_clouds(a, b) -> list[str]:
    """Names of the attributes that differ (bit for bit, NaN equal to NaN)."""
    assert len(a) == len(b)
    assert np.array_equal(a.xyz, b.xyz)
    return [n for n in a.names if not np.array_equal(a[n], b[n], equal_nan=a[n].dtype.kind == "f")]


def test_grid_owns_every_point_once_and_reaches_the_buffer():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-23.0, 41.0, (20_000, 2))
    xy[:500, 0] = np.round(xy[:500, 0] / 5.0) * 5.0  # on borders
    g = Grid(5.0, 1.3)
    i, j = g.cells(xy[:, 0], xy[:, 1])
    for a in range(-5, 9):
        x0, _, x1, _ = g.bounds(a, 0)
        m = i == a
        assert np.all((xy[m, 0] >= x0) & (xy[m, 0] < x1))
    lo, hi = g.reach(xy[:, 0])
    for a in range(-5, 9):
        x0, _, x1, _ = g.bounds(a, 0)
        near = (xy[:, 0] >= x0 - 1.3) & (xy[:, 0] <= x1 + 1.3)
        held = (lo <= a) & (hi >= a)
        assert np.all(held[near])  # every point within the buffer is read
        assert not np.any(held & ((xy[:, 0] < x0 - 1.31) | (xy[:, 0] > x1 + 1.31)))
    assert chunk_name(-3, 12) == "cm3_12"


def test_default_chunk_size_follows_density_and_budget():
    mins, maxs = np.zeros(3), np.array([1000.0, 1000.0, 10.0])
    assert default_chunk_size(100_000_000, mins, maxs, 0.5, 10_000_000) == 200.0  # 316 m -> 1-2-5 step
    assert default_chunk_size(1_000_000, mins, maxs, 0.5, 10_000_000) == 2000.0
    assert default_chunk_size(100_000_000, mins, maxs, 30.0, 1_000_000) == 100.0  # at least 4 buffers


def test_features_in_chunks_equal_the_in_memory_run(scene, run_cli):
    d, src, xyz = scene
    mem = d / "mem.las"
    rc, _, err = run_cli(["features", str(src), str(mem), "-r", "0.6", "-f", FEATURES, "-q"])
    assert rc == 0, err
    out = d / "chunked"
    rc, stdout, err = run_cli(["features", str(src), str(out), "-r", "0.6", "-f", FEATURES, "--chunk-size", "5",
                               "--workers", "1", "--json"])
    assert rc == 0, err
    s = json.loads(stdout)
    assert s["chunks"] == 12 and s["buffer"] == 0.6 and s["chunks_resumed"] == 0
    assert not (d / "chunked.lidarfx-work").exists()
    a, b = lidarfx.read(mem), lidarfx.read(out / "scene.las")
    on_border = np.isclose(np.mod(b.x - 0.0, 5.0), 0.0) | np.isclose(np.mod(b.y, 5.0), 0.0)
    assert on_border.sum() > 400
    assert _equal_clouds(a, b) == []  # the input's order and every value, bit for bit
    assert np.isfinite(b["planarity"]).mean() > 0.99
    # one output file (LAZ, merged in windows of global indices): the same, in the input's order
    one = d / "one.laz"
    rc, _, err = run_cli(["features", str(src), str(one), "-r", "0.6", "-f", FEATURES, "--chunk-size", "5",
                          "--workers", "1", "-q"])
    assert rc == 0, err
    assert _equal_clouds(a, lidarfx.read(one)) == []


def test_several_tiles_and_knn(scene, run_cli, tmp_path):
    _, _, xyz = scene
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    cut = np.floor((xyz[:, 0] - 500_100.0) / 7.0).astype(int)  # input tiles that do not follow the chunk grid
    order = np.argsort(cut, kind="stable")
    for k in np.unique(cut):
        m = np.flatnonzero(cut == k)
        _write(tiles / f"t{k}.las", xyz[m], m.astype(np.float64))
    merged = tmp_path / "merged.las"
    _write(merged, xyz[order], order.astype(np.float64))
    mem = tmp_path / "mem.las"
    rc, _, err = run_cli(["features", str(merged), str(mem), "-n", "knn", "-k", "12", "-f", "eigen", "-q"])
    assert rc == 0, err
    out = tmp_path / "out"
    rc, stdout, err = run_cli(["features", str(tiles / "t*.las"), str(out), "-n", "knn", "-k", "12", "-f", "eigen",
                               "--chunk-size", "5", "--workers", "1", "--json"])
    assert rc == 0, err
    s = json.loads(stdout)
    assert len(s["outputs"]) == len(np.unique(cut)) and 0.5 < s["buffer"] < 3.0
    got = lidarfx.PointCloud.concatenate([lidarfx.read(out / f"t{k}.las") for k in np.unique(cut)])
    assert _equal_clouds(lidarfx.read(mem), got) == []
    # a buffer narrower than the 12th neighbour: refused, naming the buffer needed
    rc, _, err = run_cli(["features", str(tiles), str(tmp_path / "out2"), "-n", "knn", "-k", "12", "-f", "eigen",
                          "--chunk-size", "5", "--buffer", "0.1", "--workers", "1", "-q"])
    assert rc == 2 and "give --buffer" in err and "Traceback" not in err
    assert not any((tmp_path / "out2").glob("*.las"))


def test_on_a_dask_cluster(scene, tmp_path, run_cli):
    import distributed  # a dependency of lidarfx (dask[distributed])
    d, src, _ = scene
    mem = tmp_path / "mem.las"
    rc, _, err = run_cli(["features", str(src), str(mem), "-r", "0.6", "-f", "eigen,msac", "-q"])
    assert rc == 0, err
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        out = tmp_path / "out"
        rc, stdout, err = run_cli(["features", str(src), str(out), "-r", "0.6", "-f", "eigen,msac", "--chunk-size",
                                   "5", "--scheduler", cl.scheduler_address, "--json"])
        assert rc == 0, err
        assert json.loads(stdout)["scheduler"] == cl.scheduler_address
        assert _equal_clouds(lidarfx.read(mem), lidarfx.read(out / "scene.las")) == []

        def boom(name):
            raise RuntimeError(f"disk on fire in {name}")

        with pytest.raises(LidarfxError, match=r"chunk c1_2 failed 2 times: RuntimeError: disk on fire"):
            execute([("c1_2", boom, ("c1_2",))], workers=2, scheduler=cl.scheduler_address, progress=False)

        tries = tmp_path / "tries"

        def wrong(name):  # a wrong option fails the same way again: not retried
            with open(tries, "a") as fh:
                fh.write(name + "\n")
            raise LidarfxError("the 8 nearest neighbours reach 3.00 m beyond the chunk; give --buffer 3")

        with pytest.raises(LidarfxError, match=r"^chunk c0_1: the 8 nearest neighbours .* give --buffer 3$"):
            execute([("c0_1", wrong, ("c0_1",))], workers=2, scheduler=cl.scheduler_address, progress=False)
        assert tries.read_text() == "c0_1\n"


def test_a_failed_chunk_is_retried_then_named(tmp_path):
    marker = tmp_path / "tried"

    def flaky(v):
        if not marker.exists():
            marker.write_text("x")
            raise OSError("transient")
        return v * 2

    assert execute([("c0_0", flaky, (21,))], workers=1, scheduler=None, progress=False) == [42]

    def broken():
        raise ValueError("bad block")

    with pytest.raises(LidarfxError, match=r"chunk c3_m1 failed 2 times: ValueError: bad block"):
        execute([("c0_0", flaky, (1,)), ("c3_m1", broken, ())], workers=1, scheduler=None, progress=False)


def test_a_killed_run_resumes_without_recomputing(scene, tmp_path, run_cli):
    d, src, xyz = scene
    mem = d / "mem_resume.las"
    rc, _, err = run_cli(["features", str(src), str(mem), "-r", "0.6", "-f", FEATURES, "-q"])
    assert rc == 0, err
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "lidarfx", "features", str(src), str(out), "-r", "0.6", "-f", FEATURES,
           "--chunk-size", "2", "--workers", "1", "-q"]
    env = {**os.environ, "PYTHONPATH": str(Path(lidarfx.__file__).parents[1])}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    done = tmp_path / "out.lidarfx-work" / "done"
    t0 = time.time()
    while time.time() - t0 < 300:
        if done.is_dir() and len(list(done.glob("*.json"))) >= 3:
            break
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = len(list(done.glob("*.json")))
    assert finished >= 3 and not out.exists()
    rc, stdout, err = run_cli(["features", str(src), str(out), "-r", "0.6", "-f", FEATURES, "--chunk-size", "2",
                               "--workers", "1", "--resume", "--json"])
    assert rc == 0, err
    s = json.loads(stdout)
    assert s["chunks"] == 80 and s["chunks_resumed"] >= finished
    assert _equal_clouds(lidarfx.read(mem), lidarfx.read(out / "scene.las")) == []
    # a resume with other options is refused, and the work folder is gone after success
    assert not (tmp_path / "out.lidarfx-work").exists()


def test_resume_refuses_other_options(scene, tmp_path, run_cli):
    _, src, _ = scene
    work = tmp_path / "w"
    rc, _, err = run_cli(["features", str(src), str(tmp_path / "a.las"), "-r", "0.6", "-f", "eigen", "--chunk-size",
                          "5", "--workers", "1", "--work-dir", str(work), "-q"])
    assert rc == 0, err
    work.mkdir()
    (work / "manifest.json").write_text(json.dumps({"version": 1, "command": "features", "options": {}}))
    rc, _, err = run_cli(["features", str(src), str(tmp_path / "b.las"), "-r", "0.6", "-f", "eigen", "--chunk-size",
                          "5", "--workers", "1", "--work-dir", str(work), "--resume", "-q"])
    assert rc == 2 and "other inputs or options" in err and not (tmp_path / "b.las").exists()
    # a folder that is not a work folder is never cleared
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    rc, _, err = run_cli(["features", str(src), str(tmp_path / "c.las"), "-r", "0.6", "-f", "eigen", "--chunk-size",
                          "5", "--workers", "1", "--work-dir", str(tmp_path / "mine"), "-q"])
    assert rc == 2 and "not a lidarfx work folder" in err
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


@pytest.mark.parametrize("argv, message", [
    (["{empty}", "{out}", "-r", "0.5"], "no .las / .laz files"),
    (["{src}", "{out}", "-r", "0.5", "--chunk-size", "-3"], "--chunk-size must be a positive number"),
    (["{src}", "{out}", "-r", "0.5", "--chunk-size", "5", "--buffer", "0.2"], "narrower than the 0.5 m"),
    (["{src}", "{out}", "-r", "0.5", "--chunk-size", "1e-6"], "give a larger chunk size"),
    (["{src}", "{out}", "-r", "0.5", "-f", "eigen,ground", "--chunk-size", "5"], "ground filter, which is not local"),
    (["{txt}", "{out}", "-r", "0.5", "--chunk-size", "5"], "tiled runs read LAS / LAZ files"),
    (["{src}", "{out}", "-r", "0.5", "--chunk-size", "0", "--resume"], "--resume and --scheduler need chunks"),
    (["{src}", "{file}", "-r", "0.5", "--chunk-size", "5"], "is not a folder"),
    (["{src}", "{out}", "-r", "0.5", "--chunk-size", "5", "--workers", "0"], "--workers must be at least 1"),
])
def test_bad_input_is_one_line_and_exit_2(scene, tmp_path, run_cli, argv, message):
    _, src, _ = scene
    (tmp_path / "empty").mkdir()
    (tmp_path / "pts.txt").write_text("1 2 3\n")
    (tmp_path / "afile").write_text("x")
    subs = {"{src}": str(src), "{out}": str(tmp_path / "out"), "{empty}": str(tmp_path / "empty"),
            "{txt}": str(tmp_path / "pts.txt"), "{file}": str(tmp_path / "afile")}
    rc, _, err = run_cli(["features", *[subs.get(a, a) for a in argv], "-q"])
    assert rc == 2, err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    assert (tmp_path / "afile").read_text() == "x"
