"""``lidarfx features`` and ``lidarfx demo`` from the command line."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx.cli import main
from lidarfx.features import compute_features


@pytest.fixture(scope="module")
def scene_las(tmp_path_factory):
    path = tmp_path_factory.mktemp("fx") / "plane.las"
    cloud = lidarfx.synth.plane(2.0, density=400.0, noise=0.005, seed=2, origin=(500000.0, 5000000.0, 200.0))
    lidarfx.write(cloud, path)
    return path


def test_features_cli_writes_float32_extra_dims(scene_las, tmp_path, capsys):
    out = tmp_path / "out.las"
    rc = main(["features", str(scene_las), str(out), "-r", "0.5", "--features", "eigen,plane,density", "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    las = laspy.read(out)
    extra = {d.name: d.dtype for d in las.point_format.extra_dimensions}
    assert set(summary["features"]) <= set(extra)
    assert all(np.dtype(extra[n]) == np.float32 for n in summary["features"])
    ref = compute_features(lidarfx.read(scene_las), "eigen,plane,density", radius=0.5)
    for name in ("planarity", "slope", "echo_ratio_slope"):
        np.testing.assert_array_equal(np.asarray(las[name]), ref[name])
    # a noisy horizontal plane: planar and flat
    assert np.nanmedian(las["planarity"]) > 0.7 and np.nanmedian(las["slope"]) < 2.0
    assert summary["points"] == len(las.points) and summary["seconds"]["features_and_write"] >= 0


def test_features_cli_leaves_features_out(scene_las, tmp_path):
    out = tmp_path / "left.laz"
    assert main(["features", str(scene_las), str(out), "-r", "0.5", "-f", "eigen,plane,-slope,-plane_std", "-q"]) == 0
    names = {d.name for d in laspy.read(out).point_format.extra_dimensions}
    assert {"planarity", "plane_distance", "plane_inlier_ratio"} <= names
    assert not names & {"slope", "plane_std"}


def test_features_cli_multiscale_names(scene_las, tmp_path):
    out = tmp_path / "multi.laz"
    assert main(["features", str(scene_las), str(out), "-r", "0.3", "-r", "0.6", "-f", "planarity", "-q"]) == 0
    names = {d.name for d in laspy.read(out).point_format.extra_dimensions}
    assert {"planarity_r0.30", "planarity_r0.60"} <= names


@pytest.mark.parametrize(
    "args,message",
    [
        (["-r", "0.5", "--features", "planarty"], "unknown feature 'planarty'"),
        (["-r", "0.5", "--features", "eigen,-slope"], "cannot leave out 'slope'"),
        (["--features", "eigen"], "give a radius"),
        (["-r", "-1"], "radii must be positive"),
        (["-n", "knn"], "k >= 1"),
        # before these checks: a traceback (numba cannot type the int), a 477 TiB allocation, a run of
        # hours (10^8 bins per thread), and distances that only produced garbage ratios
        (["-r", "0.5", "-f", "msac", "--seed", "99999999999999999999999"], "seed must be an integer from 0 to 4294967295"),
        (["-r", "0.5", "--seed", "-1"], "seed must be an integer from 0"),
        (["-n", "knn", "-k", "1000000000"], "k must be at most 10000 neighbours"),
        (["-r", "0.5", "-f", "histogram", "--bins", "100000000"], "hist_bins must be an integer from 2 to 1000"),
        (["-r", "0.5", "--d-max", "-1"], "d_max (the plane inlier distance) must be a positive finite distance"),
        (["-r", "0.5", "--d-max", "nan"], "must be a positive finite distance, got nan"),
        (["-r", "0.5", "--d-max", "inf"], "must be a positive finite distance, got inf"),
        (["-r", "1e-300"], "radii must be at least 1e-09, got 1e-300"),  # a ZeroDivisionError in classify
        (["-r", "1e-9"], "the radius is too small for the cloud's extent"),  # int64 column keys overflowed
    ],
)
def test_features_cli_errors(scene_las, tmp_path, capsys, args, message):
    out = tmp_path / "bad.las"
    assert main(["features", str(scene_las), str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob(".bad*"))


def test_features_cli_refuses_to_overwrite_input(scene_las, capsys):
    before = scene_las.read_bytes()
    assert main(["features", str(scene_las), str(scene_las), "-r", "0.5"]) == 2
    assert scene_las.read_bytes() == before


def test_features_list_and_subprocess_exit_code(tmp_path):
    res = subprocess.run([sys.executable, "-m", "lidarfx", "features", "--list"], capture_output=True, text=True)
    assert res.returncode == 0 and "planarity" in res.stdout and "echo_ratio_slope" in res.stdout
    res = subprocess.run(
        [sys.executable, "-m", "lidarfx", "features", str(tmp_path / "missing.laz"), str(tmp_path / "o.laz"), "-r", "1"],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2 and "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_demo_scenes_meet_their_targets(tmp_path):
    """Two scenes of the demo: products, pictures, reports and an index, with the figures against
    the scenes' truth (the whole demo runs in the slow tests and in CI's Quick-start check)."""
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--scenes", "rockface,house", "-q"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [s["name"] for s in summary["scenes"]] == ["rockface", "house"]
    figures = {(s["name"], f["measure"]): f for s in summary["scenes"] for f in s["figures"]}
    assert figures[("rockface", "sets found (true: 3)")]["value"] == 3
    assert figures[("rockface", "largest angle to the true set, °")]["value"] < 1.0
    assert figures[("house", "ridge covered (share of its length)")]["value"] >= 0.9
    assert all(s["passed"] for s in summary["scenes"])
    for name, files in ((s["name"], s["files"]) for s in summary["scenes"]):
        assert (out / name / "index.html").stat().st_size > 0
        for path in files.values():
            assert Path(path).stat().st_size > 0
    index = (out / "index.html").read_text()
    assert 'href="rockface/index.html"' in index and 'href="house/index.html"' in index
    assert (out / "house" / "edges.geojson").exists() and (out / "rockface" / "stereonet.png").exists()


def test_demo_refuses_an_unknown_scene(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d"), "--scenes", "castle"]) == 2
    assert "unknown demo scene 'castle'" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


@pytest.mark.slow
def test_whole_demo_meets_every_target(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "-q"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [s["name"] for s in summary["scenes"]] == ["facade", "rockface", "powerline", "house", "dike"]
    missed = [(s["name"], f["measure"], f["value"]) for s in summary["scenes"] for f in s["figures"] if f["pass"] is False]
    assert not missed


@pytest.mark.parametrize("ext", [".laz", ".npz", ".ply"])
def test_features_cli_streams_into_every_format(scene_las, tmp_path, ext):
    """LAS/LAZ get the features chunk by chunk while writing; other formats collect
    them first — the values are the same either way."""
    out = tmp_path / f"stream{ext}"
    assert main(["features", str(scene_las), str(out), "-r", "0.4", "-f", "planarity,slope", "-q"]) == 0
    got = lidarfx.read(out)
    ref = compute_features(lidarfx.read(scene_las), "planarity,slope", radius=0.4)
    for name in ("planarity", "slope"):
        np.testing.assert_allclose(got[name], ref[name], rtol=1e-6, equal_nan=True)


def test_features_help_names_every_group():
    import re

    from lidarfx.cli.features import EPILOG
    from lidarfx.features.registry import available

    text = " ".join(EPILOG.split())
    listed = set(re.findall(r"[a-z_]+", text[text.index("feature groups:"):]))
    assert set(available()) <= listed, set(available()) - listed


@pytest.mark.parametrize("pos", ["nan,0,0", "0,inf,0"])
def test_a_position_must_be_finite(scene_las, tmp_path, capsys, pos):
    """`--scanner nan,0,0` was accepted and turned the normals up or down at random."""
    with pytest.raises(SystemExit) as exc:
        main(["features", str(scene_las), str(tmp_path / "o.laz"), "-r", "0.5", "--scanner", pos])
    assert exc.value.code == 2
    assert f"a position x,y,z must be finite numbers, got '{pos}'" in capsys.readouterr().err
    assert not (tmp_path / "o.laz").exists()
    with pytest.raises(lidarfx.LidarfxError, match="scanner position must be three finite numbers"):
        lidarfx.features.stream_features(lidarfx.read(scene_las), "plane", radius=0.5,
                                         scanner=[float(v) for v in pos.split(",")])


def test_a_position_may_start_with_a_minus_sign(scene_las, tmp_path):
    """`--scanner -1,2,3` was refused by argparse ("expected one argument"): a value starting with
    '-' is taken for an option unless it is one plain number.  It now reads as --scanner=-1,2,3."""
    from lidarfx.cli._args import join_number_lists

    assert join_number_lists(["features", "--scanner", "-1,2,3", "-r", "-1"]) == [
        "features", "--scanner=-1,2,3", "-r", "-1"]
    assert join_number_lists(["synth", "plane", "p.laz", "--origin", "-5e5,-2.5,0", "--rotation", "random"]) == [
        "synth", "plane", "p.laz", "--origin=-5e5,-2.5,0", "--rotation", "random"]
    out, ref = tmp_path / "a.laz", tmp_path / "b.laz"
    assert main(["features", str(scene_las), str(out), "-r", "0.5", "-f", "plane", "--scanner", "-1,2,3", "-q"]) == 0
    assert main(["features", str(scene_las), str(ref), "-r", "0.5", "-f", "plane", "--scanner=-1,2,3", "-q"]) == 0
    np.testing.assert_array_equal(lidarfx.read(out)["normal_z"], lidarfx.read(ref)["normal_z"])
