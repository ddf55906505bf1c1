"""Outputs and interruptions (docs/reliability.md): inputs are never modified; an existing output
is refused before any work unless --force; a run killed with SIGKILL at any moment leaves no
output that is not complete and identical to an uninterrupted run's (one file, and a chunked
run on a Dask cluster that is then resumed); a full disk (file size limit, an injected ENOSPC,
a full tmpfs) is one line, exit code 1, no output and no temporary file."""
from __future__ import annotations

import errno
import hashlib
import json
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx import synth
from lidarfx._atomic import OVERWRITE, atomic_path, check_new_folder, is_temporary
from lidarfx.errors import LidarfxError
from lidarfx.io import las as las_io

ENV = {**os.environ, "PYTHONPATH": str(Path(lidarfx.__file__).parents[1]), "LIDARFX_COMPILE_NOTICE": "0"}
ENOSPC_LINE = "no space left on device writing"


# ------------------------------------------------------------------------------ helpers
@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Small synthetic inputs (a few thousand points each) in their own folder."""
    d = tmp_path_factory.mktemp("inputs")
    house = synth.house(seed=0, margin=2.0, density=10.0)
    n = len(house)
    house["return_number"] = np.ones(n, np.uint8)  # ALS returns, as the default model expects
    house["number_of_returns"] = np.where(np.arange(n) % 7 == 0, 2, 1).astype(np.uint8)
    lidarfx.write(house, d / "house.laz")
    lidarfx.write(synth.terrain(seed=0, size=40.0, density=3.0), d / "terrain.laz")
    lidarfx.write(synth.powerline(seed=0, n_spans=1, span_length=100.0, density=1.0, wire_density=2.0,
                                  pylon_density=3.0, corridor_width=30.0, n_trees=2, n_near_trees=1),
                  d / "corridor.laz")
    lidarfx.write(synth.house(seed=1, margin=4.0, density=40.0), d / "big.laz")  # a longer run to kill
    return d


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def temporaries(folder: Path) -> list[Path]:
    """Temporary files of lidarfx.atomic_path anywhere under ``folder``."""
    return sorted(p for p in Path(folder).rglob("*") if is_temporary(p.name))


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lidarfx: error: ") and "Traceback" not in err, err
    return lines[0]


def same_points(a: Path, b: Path) -> bool:
    """The same point records (every field, bit for bit), point count and format."""
    la, lb = laspy.read(str(a)), laspy.read(str(b))
    return (la.header.point_format.id == lb.header.point_format.id and la.header.point_count == lb.header.point_count
            and list(la.point_format.dimension_names) == list(lb.point_format.dimension_names)
            and la.points.array.tobytes() == lb.points.array.tobytes())


def lidarfx_process(argv: list[str], **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "lidarfx", *argv], env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (Dask's nannies and workers)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def kill_after(argv: list[str], delay: float) -> int:
    """Start ``lidarfx argv``, SIGKILL it after ``delay`` seconds (if still running), wait until it and
    every process it started are gone; returns its exit code (-9 when killed)."""
    proc = lidarfx_process(argv)
    t0 = time.perf_counter()
    kids: set[int] = set()
    while time.perf_counter() - t0 < delay and proc.poll() is None:
        kids.update(descendants(proc.pid))
        time.sleep(0.01)
    kids.update(descendants(proc.pid))
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    proc.communicate()
    t1 = time.perf_counter()
    while any(Path(f"/proc/{k}").exists() and "zombie" not in _state(k) for k in kids):
        assert time.perf_counter() - t1 < 60, "the processes of a killed run did not stop"
        time.sleep(0.1)
    return proc.returncode


def _state(pid: int) -> str:
    try:
        return (Path(f"/proc/{pid}") / "status").read_text().split("State:", 1)[1].split("\n", 1)[0].lower()
    except (OSError, IndexError):
        return "zombie"


def spread_delays(seed: int, total: float, n: int, lo: float = 0.05, hi: float = 1.05) -> list[float]:
    """``n`` seeded random delays, one in each of ``n`` equal parts of [lo, hi] x ``total``."""
    rng = random.Random(seed)
    step = (hi - lo) / n
    return [total * (lo + (k + rng.random()) * step) for k in range(n)]


# ------------------------------------------------------------------- inputs never modified
def _commands(d: Path, o: Path) -> dict[str, list[str]]:
    seg = ["--normal-radius", "0.91", "--growing-radius", "0.7", "--max-distance", "0.1", "--min-width", "0.7"]
    return {
        "features": ["features", str(d / "house.laz"), str(o / "f.laz"), "-r", "1", "-f", "eigen,plane,density"],
        "ground": ["ground", str(d / "terrain.laz"), str(o / "g.laz"), "--hag", "--dtm", str(o / "dtm.asc")],
        "segment": ["segment", str(d / "house.laz"), str(o / "s.laz"), *seg],
        "thin": ["thin", str(d / "house.laz"), str(o / "t.laz"), "--cell", "0.5"],
        "classify predict": ["classify", "predict", str(d / "house.laz"), str(o / "c.laz"), "--model", "default"],
        "edges": ["edges", str(d / "house.laz"), str(o / "e.geojson"), "--csv", "--dxf", str(o / "e.dxf")],
        "breaklines": ["breaklines", str(d / "terrain.laz"), str(o / "b.geojson"), "--csv"],
        "powerlines": ["powerlines", str(d / "corridor.laz"), str(o / "wires")],
        "render": ["render", str(d / "house.laz"), str(o / "r.png")],
        "convert": ["convert", str(d / "house.laz"), str(o / "c.ply")],
    }


@pytest.mark.parametrize("command", list(_commands(Path("."), Path("."))))
def test_inputs_are_never_modified(scenes, tmp_path, run_cli, command):
    argv = _commands(scenes, tmp_path)[command]
    before = {p.name: (sha256(p), p.stat().st_mtime_ns) for p in scenes.iterdir()}
    rc, _, err = run_cli([*argv, *(["-q"] if command != "convert" else [])])
    assert rc == 0, err
    assert {p.name: (sha256(p), p.stat().st_mtime_ns) for p in scenes.iterdir()} == before  # nothing new there
    written = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert written and not temporaries(tmp_path)


# ---------------------------------------------------------------------------------- --force
def test_an_existing_file_is_refused_before_any_work_and_replaced_with_force(scenes, tmp_path, run_cli, monkeypatch):
    src, out = scenes / "house.laz", tmp_path / "out.ply"
    out.write_bytes(b"an older file")

    def no_reading(*a, **k):
        raise AssertionError("the input was read")

    with monkeypatch.context() as m:  # refused before the input is read
        m.setattr(lidarfx.io, "read", no_reading)
        rc, _, err = run_cli(["convert", str(src), str(out)])
    assert rc == 2 and one_error_line(err) == f"lidarfx: error: {out} exists; give --force to overwrite it"
    assert out.read_bytes() == b"an older file" and not temporaries(tmp_path)
    rc, _, err = run_cli(["convert", str(src), str(out), "--force"])
    assert rc == 0, err
    assert np.array_equal(lidarfx.read(out).xyz, lidarfx.read(src).xyz)
    # in-process twice: the second run is refused, --force (also before the command) replaces
    f = tmp_path / "f.laz"
    argv = ["features", str(src), str(f), "-r", "1", "-f", "eigen", "-q"]
    assert run_cli(argv)[0] == 0
    first = f.stat().st_mtime_ns
    rc, _, err = run_cli(argv)
    assert rc == 2 and "f.laz exists; give --force" in one_error_line(err) and f.stat().st_mtime_ns == first
    assert run_cli(["--force", *argv])[0] == 0 and f.stat().st_mtime_ns != first
    # after a run the library writes where it is told again (like numpy.save)
    assert OVERWRITE.get() is True
    lidarfx.write(lidarfx.read(src), f)
    assert "planarity" not in lidarfx.read(f)


def test_line_products_are_refused_when_any_of_their_files_exists(scenes, tmp_path, run_cli):
    src = scenes / "house.laz"
    geo, dxf = tmp_path / "lines.geojson", tmp_path / "lines.dxf"
    argv = ["edges", str(src), str(geo), "--csv", "--dxf", str(dxf), "-q"]
    (tmp_path / "lines.lines.json").write_text("mine")  # the JSON of --csv: the last file of the product
    rc, _, err = run_cli(argv)
    assert rc == 2 and "lines.lines.json exists; give --force" in one_error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lines.lines.json"]  # nothing else written
    rc, _, err = run_cli([*argv, "--force"])
    assert rc == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lines.csv", "lines.dxf", "lines.geojson", "lines.lines.json"]
    assert json.loads((tmp_path / "lines.lines.json").read_text())["lines"]
    rc, _, err = run_cli(argv)  # every file of a finished product is an existing output
    assert rc == 2 and "exists; give --force" in one_error_line(err)


def test_folder_outputs_need_an_empty_folder_or_force(scenes, tmp_path, run_cli):
    src = scenes / "corridor.laz"
    out = tmp_path / "wires"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    rc, _, err = run_cli(["powerlines", str(src), str(out), "-q"])
    assert rc == 2 and one_error_line(err) == (f"lidarfx: error: {out} is not empty; give --force to write into it "
                                               "(files of the same name are replaced)")
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    rc, _, err = run_cli(["powerlines", str(src), str(out), "-q", "--force"])
    assert rc == 0, err
    assert (out / "wires.geojson").is_file() and (out / "notes.txt").read_text() == "keep"  # never deletes
    # a report folder holds one file, index.html: refused only when that exists
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "other.txt").write_text("x")
    argv = ["features", str(scenes / "house.laz"), str(tmp_path / "f.laz"), "-r", "1", "-f", "eigen", "-q",
            "--report", str(rep)]
    assert run_cli(argv)[0] == 0 and (rep / "index.html").is_file()
    rc, _, err = run_cli([*argv[:2], str(tmp_path / "f2.laz"), *argv[3:]])
    assert rc == 2 and "index.html exists; give --force" in one_error_line(err)
    assert not (tmp_path / "f2.laz").exists()


def test_chunked_outputs_are_checked_before_the_split(scenes, tmp_path, run_cli):
    src = scenes / "house.laz"
    out = tmp_path / "out.laz"
    out.write_bytes(b"old")
    rc, _, err = run_cli(["features", str(src), str(out), "-r", "1", "--chunk-size", "10", "--workers", "1", "-q"])
    assert rc == 2 and "out.laz exists; give --force" in one_error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.laz"]  # no work folder
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    (tiles / "house.laz").write_bytes(b"old")
    rc, _, err = run_cli(["features", str(src), str(tiles), "-r", "1", "--workers", "1", "-q"])
    assert rc == 2 and "is not empty; give --force" in one_error_line(err)
    rc, _, err = run_cli(["features", str(src), str(tiles), "-r", "1", "--workers", "1", "-q", "--force"])
    assert rc == 0, err
    assert len(lidarfx.read(tiles / "house.laz")) == len(lidarfx.read(src))


def test_the_last_guard_at_the_rename(tmp_path):
    """An output that appears while the run works is not replaced: the temporary file goes."""
    target = tmp_path / "a.txt"
    token = OVERWRITE.set(False)
    try:
        with pytest.raises(LidarfxError, match="a.txt exists; give --force"):
            with atomic_path(target) as tmp:
                tmp.write_text("new")
                target.write_text("appeared meanwhile")
        assert target.read_text() == "appeared meanwhile" and not temporaries(tmp_path)
        with pytest.raises(LidarfxError, match="is not empty"):
            check_new_folder(tmp_path)
    finally:
        OVERWRITE.reset(token)
    with atomic_path(target) as tmp:  # the Python API replaces
        tmp.write_text("new")
    assert target.read_text() == "new"


def test_temporary_files_of_killed_runs_are_removed_by_the_next_write(tmp_path):
    from lidarfx._atomic import _HOST

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    stale = tmp_path / f".out.lidarfx-{_HOST}-{dead}-abcd1234.part.laz"
    live = tmp_path / f".out.lidarfx-{_HOST}-{os.getppid()}-abcd1234.part.laz"  # a running process's
    other = tmp_path / f".out.lidarfx-elsewhere-{dead}-abcd1234.part.laz"  # another host's: unknown
    for p in (stale, live, other):
        p.write_bytes(b"partial")
    token = OVERWRITE.set(False)
    try:
        check_new_folder(tmp_path)  # temporary files alone do not make a folder an output
    finally:
        OVERWRITE.reset(token)
    with atomic_path(tmp_path / "out.laz") as tmp:
        tmp.write_bytes(b"x")
    assert not stale.exists() and live.exists() and other.exists()


# --------------------------------------------------------------------------- SIGKILL
def test_sigterm_stops_a_run_and_removes_its_temporary_file(scenes, tmp_path):
    """SIGTERM (kill PID, a batch system's time limit) while the output is being written: exit code
    143, one line, no output and no temporary file left."""
    out = tmp_path / "out.laz"
    proc = lidarfx_process(["features", str(scenes / "big.laz"), str(out), "-r", "1", "-f", "eigen,plane,msac", "-q"])
    mine = f"-{proc.pid}-"
    while not any(mine in t.name for t in temporaries(tmp_path)) and proc.poll() is None:
        time.sleep(0.002)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert err.strip() == "lidarfx: terminated"
    assert list(tmp_path.iterdir()) == []


def test_a_killed_run_leaves_its_output_complete_or_absent(scenes, tmp_path):
    src = scenes / "big.laz"
    ref = tmp_path / "ref.laz"
    argv = ["features", str(src), "{out}", "-r", "1", "-f", "eigen,plane,msac", "-q"]
    for target in (ref, tmp_path / "again.laz"):  # the first also fills numba's cache: the second is timed
        t0 = time.perf_counter()
        p = lidarfx_process([a.replace("{out}", str(target)) for a in argv])
        _, err = p.communicate()
        total = time.perf_counter() - t0
        assert p.returncode == 0, err
    assert sha256(tmp_path / "again.laz") == sha256(ref)
    work = tmp_path / "run"
    work.mkdir()
    out = work / "out.laz"
    run = [a.replace("{out}", str(out)) for a in argv] + ["--force"]
    seen_temporary = False
    # at random moments over the whole run, then the moment its temporary file is seen
    for delay in [*spread_delays(7, total, 4), None]:
        if delay is None:
            proc = lidarfx_process(run)
            mine = f"-{proc.pid}-"  # its own temporary file, not one an earlier kill left
            while not any(mine in t.name for t in temporaries(work)) and proc.poll() is None:
                time.sleep(0.002)
            proc.send_signal(signal.SIGKILL)
            proc.communicate()
            rc = proc.returncode
            assert rc == -signal.SIGKILL and any(mine in t.name for t in temporaries(work)), "killed while writing"
        else:
            rc = kill_after(run, delay)
        assert rc in (0, -signal.SIGKILL)
        if out.exists():
            assert same_points(out, ref) and sha256(out) == sha256(ref)
        left = {p.name for p in work.iterdir()} - {"out.laz"}
        assert all(is_temporary(n) for n in left), left  # nothing but a killed run's temporary files
        seen_temporary |= bool(left)
    assert seen_temporary
    # the next run removes what killed runs left and writes the same output
    proc = lidarfx_process(run)
    _, err = proc.communicate()
    assert proc.returncode == 0, err
    assert [p.name for p in work.iterdir()] == ["out.laz"] and sha256(out) == sha256(ref)


def _chunked_kill(scenes, tmp_path, seed: int, kills: int) -> None:
    src = scenes / "big.laz"
    argv = ["features", str(src), "{out}", "-r", "1", "-f", "eigen,plane,density", "--chunk-size", "8",
            "--workers", "2", "-q"]
    ref = tmp_path / "ref" / "ref.laz"
    ref.parent.mkdir()
    warm = lidarfx_process([*argv[:2], str(tmp_path / "warm.laz"), *argv[3:7], "-q"])  # numba's cache filled
    assert warm.communicate() and warm.returncode == 0
    t0 = time.perf_counter()
    p = lidarfx_process([a.replace("{out}", str(ref)) for a in argv])
    _, err = p.communicate()
    total = time.perf_counter() - t0
    assert p.returncode == 0, err
    assert sorted(p.name for p in ref.parent.iterdir()) == ["ref.laz"]  # the work folder is gone
    interrupted = 0
    for k, delay in enumerate(spread_delays(seed, total, kills, lo=0.3, hi=1.0)):
        folder = tmp_path / f"kill{k}"
        folder.mkdir()
        out = folder / "out.laz"
        run = [a.replace("{out}", str(out)) for a in argv]
        rc = kill_after(run, delay)
        assert rc in (0, -signal.SIGKILL)
        if out.exists():
            assert same_points(out, ref)
        left = {p.name for p in folder.iterdir()} - {"out.laz", "out.laz.lidarfx-work"}
        assert all(is_temporary(n) for n in left), left
        done = folder / "out.laz.lidarfx-work" / "done"
        finished = len(list(done.glob("*.json"))) if done.is_dir() else 0
        interrupted += rc == -signal.SIGKILL and done.is_dir()  # killed in the middle of the run
        resume = [*run, "--resume", "--json"]
        if out.exists():  # a finished output is replaced only with --force, resumed or not
            p = lidarfx_process(resume)
            _, err = p.communicate()
            assert p.returncode == 2 and "out.laz exists; give --force" in one_error_line(err)
            resume.append("--force")
        p = lidarfx_process(resume)
        stdout, err = p.communicate()
        assert p.returncode == 0, err
        assert json.loads(stdout)["chunks_resumed"] >= finished
        assert same_points(out, ref)
        assert sorted(p.name for p in folder.iterdir()) == ["out.laz"]  # no work folder, no temporary file
    assert interrupted


def test_a_killed_chunked_run_resumes_to_the_same_output(scenes, tmp_path):
    _chunked_kill(scenes, tmp_path, seed=3, kills=2)


@pytest.mark.slow
def test_a_chunked_run_killed_at_many_moments_resumes_to_the_same_output(scenes, tmp_path):
    _chunked_kill(scenes, tmp_path, seed=11, kills=6)


# --------------------------------------------------------------------------- disk full
def _limited(limit: int):
    def pre() -> None:  # in the child: writes beyond ``limit`` bytes fail with EFBIG
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return pre


@pytest.mark.parametrize("name, extra", [
    ("out.laz", ["features", "-r", "1", "-f", "eigen"]),  # LAZ through lazrs
    ("out.las", ["features", "-r", "1", "-f", "eigen"]),
    ("out.ply", ["convert"]),
    ("out.xyz", ["convert"]),
])
def test_a_file_size_limit_is_one_line_and_exit_1(scenes, tmp_path, name, extra):
    src = scenes / "house.laz"
    argv = [extra[0], str(src), str(tmp_path / name), *extra[1:]]
    p = lidarfx_process([*argv[:2], str(tmp_path / ("ref" + name[3:])), *argv[3:]])  # warm, and the size
    _, err = p.communicate()
    assert p.returncode == 0, err
    limit = 64 * 1024
    assert (tmp_path / ("ref" + name[3:])).stat().st_size > 2 * limit
    p = lidarfx_process(argv, preexec_fn=_limited(limit))
    _, err = p.communicate()
    assert p.returncode == 1
    assert one_error_line(err) == f"lidarfx: error: file too large writing {tmp_path / name}"
    assert not (tmp_path / name).exists() and not temporaries(tmp_path)


def test_a_chunked_run_on_a_full_disk_resumes_later(scenes, tmp_path):
    src = scenes / "big.laz"
    out = tmp_path / "out.laz"
    argv = ["features", str(src), str(out), "-r", "1", "-f", "eigen", "--chunk-size", "8", "--workers", "1", "-q"]
    p = lidarfx_process(argv, preexec_fn=_limited(256 * 1024))
    _, err = p.communicate()
    assert p.returncode == 1
    line = one_error_line(err)
    assert line.startswith("lidarfx: error: file too large writing ") and "out.laz" in line
    assert not out.exists() and not temporaries(tmp_path)
    p = lidarfx_process([*argv, "--resume"])  # with space again: the kept work goes on
    _, err = p.communicate()
    assert p.returncode == 0, err
    assert [p.name for p in tmp_path.iterdir()] == ["out.laz"]
    assert np.array_equal(lidarfx.read(out)["planarity"],
                          lidarfx.compute_features(lidarfx.read(src), "eigen", radius=1.0)["planarity"], equal_nan=True)


def _enospc(path, *a, **k):
    Path(path).write_bytes(b"half a file")
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _cloud_enospc(cloud, path, *a, **k):  # a format module's write(cloud, path, ...)
    _enospc(path)


def _merge_enospc(path, *a, _write=las_io.write_records, **k):  # the merge's, not the split's
    if ".part" in Path(path).name:
        _enospc(path)
    return _write(path, *a, **k)


def _injections():
    """(what, the writer to replace, its replacement, argv with {src} {out} {dir}, the output)"""
    def savefig(self, path, *a, **k):
        _enospc(path)

    def parts(self):
        yield "<html>"
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    return [
        ("LAZ", "lidarfx.io.las.write", _cloud_enospc, ["convert", "{src}", "{out}"], "out.laz"),
        ("PLY", "lidarfx.io.ply.write", _cloud_enospc, ["convert", "{src}", "{out}"], "out.ply"),
        ("text", "lidarfx.io.ascii.write", _cloud_enospc, ["convert", "{src}", "{out}"], "out.csv"),
        ("GeoJSON", "lidarfx.vector.export._write_geojson_to", _enospc, ["edges", "{src}", "{out}", "-q"],
         "lines.geojson"),
        ("DXF", "lidarfx.vector.export._write_dxf_to", _enospc,
         ["edges", "{src}", "{dir}/lines.geojson", "--dxf", "{out}", "-q"], "lines.dxf"),
        ("CSV", "lidarfx.vector.export._write_csv_to", _enospc,
         ["edges", "{src}", "{dir}/lines.geojson", "--csv", "{out}", "-q"], "lines.csv"),
        ("raster", "numpy.savetxt", lambda fh, *a, **k: (fh.write("ncols"), _raise_enospc()),
         ["dtm", "{terrain}", "{out}", "-q"], "dtm.asc"),
        ("PNG", "matplotlib.figure.Figure.savefig", savefig, ["render", "{src}", "{out}", "-q"], "r.png"),
        ("report page", "lidarfx.report.Report._parts", parts,
         ["report", "{src}", "{dir}/rep", "-q", "--no-picture"], "rep/index.html"),
        ("chunked merge", "lidarfx.io.las.write_records", _merge_enospc,
         ["features", "{src}", "{out}", "-r", "1", "-f", "eigen", "--chunk-size", "10", "--workers", "1", "-q"],
         "out.laz"),
    ]


def _raise_enospc():
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("what, target, fake, argv, name", _injections(), ids=[i[0] for i in _injections()])
def test_an_injected_enospc_is_one_line_and_exit_1(scenes, tmp_path, run_cli, monkeypatch, what, target, fake, argv,
                                                   name):
    monkeypatch.setattr(target, fake)
    out = tmp_path / name
    subs = {"{src}": str(scenes / "house.laz"), "{terrain}": str(scenes / "terrain.laz"), "{out}": str(out)}
    rc, _, err = run_cli([subs.get(a, a.replace("{dir}", str(tmp_path))) for a in argv])
    assert rc == 1
    assert one_error_line(err) == f"lidarfx: error: {ENOSPC_LINE} {out}"
    assert not out.exists() and not temporaries(tmp_path)
    if what == "chunked merge":  # the chunks are kept for --resume, beside the output
        assert sorted(p.name for p in tmp_path.iterdir()) == ["out.laz.lidarfx-work"]
    else:
        assert not [p for p in tmp_path.rglob("*") if p.is_file()]


def test_out_of_memory_is_one_line_and_exit_1(scenes, tmp_path, run_cli, monkeypatch):
    def no_memory(cloud, path, *a, **k):
        Path(path).write_bytes(b"half a file")
        raise MemoryError()

    monkeypatch.setattr("lidarfx.io.ply.write", no_memory)
    rc, _, err = run_cli(["convert", str(scenes / "house.laz"), str(tmp_path / "d.ply")])
    assert rc == 1 and one_error_line(err) == "lidarfx: error: out of memory"
    assert not (tmp_path / "d.ply").exists() and not temporaries(tmp_path)


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 1 MiB tmpfs (skipped where mounting is not permitted)."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True, text=True,
                           timeout=30)
    except (OSError, subprocess.SubprocessError) as exc:
        pytest.skip(f"cannot mount a tmpfs here: {exc}")
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True, timeout=30)


def test_a_full_file_system_keeps_the_old_output(scenes, small_tmpfs, run_cli):
    src = scenes / "big.laz"
    out = small_tmpfs / "out.las"
    out.write_bytes(b"the output of an earlier run")
    rc, _, err = run_cli(["features", str(src), str(out), "-r", "1", "-f", "eigen,plane", "-q", "--force"])
    assert rc == 1 and one_error_line(err) == f"lidarfx: error: {ENOSPC_LINE} {out}"
    assert out.read_bytes() == b"the output of an earlier run"  # a failed replacement keeps the old file
    assert [p.name for p in small_tmpfs.iterdir()] == ["out.las"]
