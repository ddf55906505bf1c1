"""``lidarfx info`` and ``lidarfx convert`` (in-process and as a subprocess)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

from lidarfx.cli import main
import lidarfx
from lidarfx.io import read

REAL = (Path(__file__).parents[1] / ".." / "shared" / "data" / "real").resolve()
SRC = Path(__file__).parents[1] / "src"

REAL_LAS = [
    "12AN2_20.laz",
    "AHN3.laz",
    "MixedConifer.laz",
    "TO_core_last_zoom.laz",
    "Topography.laz",
    "autzen_trim.laz",
    "crop_1.laz",
    "file_with_both_wkt_and_geotiff_vlrs.las",
    "fusa.laz",
    "lake.laz",
    "lone-star.laz",
    "plane.laz",
    "pont.laz",
    "samp11-utm.laz",
    "samp21-utm.laz",
    "samp23-utm.laz",
    "samp31-utm.laz",
    "samp41-utm.laz",
    "samp51-utm.laz",
    "samp53-utm.laz",
    "samp61-utm.laz",
    "sample_c.las",
    "test_data_77050_627755_LA93_IGN69.laz",
    "test_data_77055_627755_LA93_IGN69.laz",
    "test_data_77060_627755_LA93_IGN69.laz",
    "warsaw_small.las",
]


def real(name: str) -> Path:
    path = REAL / name
    if not path.exists():
        pytest.skip(f"real data not found: {path}")
    return path


def run_json(capsys, *argv: str):
    assert main(["info", "--json", *argv]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("name", REAL_LAS)
def test_info_json_matches_laspy(capsys, name):
    path = real(name)
    ref = laspy.read(path)
    res = run_json(capsys, str(path))
    assert res["points"] == len(ref.points) == ref.header.point_count
    codes, counts = np.unique(np.asarray(ref.classification), return_counts=True)
    assert [(c["code"], c["count"]) for c in res["classes"]] == list(zip(codes.tolist(), counts.tolist()))
    assert res["bounds"]["min"] == [float(ref.x.min()), float(ref.y.min()), float(ref.z.min())]
    assert res["bounds"]["max"] == [float(ref.x.max()), float(ref.y.max()), float(ref.z.max())]
    rn, rc = np.unique(np.asarray(ref.return_number), return_counts=True)
    assert res["returns"]["return_number"] == {str(k): v for k, v in zip(rn.tolist(), rc.tolist())}
    assert res["las"]["version"] == str(ref.header.version)
    assert res["las"]["point_format"] == ref.point_format.id
    assert res["las"]["scales"] == ref.header.scales.tolist()
    assert list(res["attributes"]) == [d for d in ref.point_format.dimension_names if d not in ("X", "Y", "Z")]


def test_info_json_several_files_is_a_list(capsys):
    a, b = real("samp21-utm.laz"), real("warsaw_small.las")
    res = run_json(capsys, str(a), str(b))
    assert [r["points"] for r in res] == [12_960, 3_000]
    assert res[0]["crs"]["epsg"] == 32632


def test_info_table(capsys):
    path = real("crop_1.laz")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    for text in ("210,582", "EPSG:2154", "high vegetation", "66,454", "ScanChannel (uint8)", "LAS 1.4, point format 6"):
        assert text in out, text


def test_info_of_text_file(tmp_path, capsys):
    (tmp_path / "a.txt").write_text("x y z classification\n0 0 0 2\n1 1 1 2\n2 2 2 6\n")
    res = run_json(capsys, str(tmp_path / "a.txt"))
    assert res["points"] == 3 and res["format"] == "ascii" and res["las"] is None
    assert res["classes"] == [{"code": 2, "name": "ground", "count": 2}, {"code": 6, "name": "building", "count": 1}]
    assert res["density"]["unit_assumed"] is True


def test_convert_text_with_columns_to_laz(tmp_path, capsys):
    (tmp_path / "in.pts").write_text("10.5 20.25 3 120 2\n11.5 21.25 4 130 5\n")
    out = tmp_path / "out.laz"
    assert main(["convert", str(tmp_path / "in.pts"), str(out), "--columns", "x,y,z,intensity,classification"]) == 0
    assert "2 points" in capsys.readouterr().out
    ref = laspy.read(out)
    assert ref.header.point_format.id == 6
    assert ref.classification.tolist() == [2, 5] and ref.intensity.tolist() == [120, 130]
    assert np.allclose(np.column_stack([ref.x, ref.y, ref.z]), [[10.5, 20.25, 3], [11.5, 21.25, 4]])


def test_convert_las_to_ascii_ply_and_back(tmp_path):
    src = real("warsaw_small.las")
    assert main(["convert", str(src), str(tmp_path / "w.ply"), "--ascii"]) == 0
    assert b"format ascii 1.0" in (tmp_path / "w.ply").read_bytes()[:100]
    cloud, ref = read(tmp_path / "w.ply"), laspy.read(src)
    assert np.array_equal(cloud.xyz, np.column_stack([ref.x, ref.y, ref.z]))
    assert np.array_equal(cloud["classification"], ref.classification)


def test_convert_laz_to_las_passes_header_through(tmp_path):
    src = real("test_data_77055_627755_LA93_IGN69.laz")
    assert main(["convert", str(src), str(tmp_path / "tile.las")]) == 0
    a, b = laspy.read(src), laspy.read(tmp_path / "tile.las")
    assert not laspy.open(tmp_path / "tile.las").header.are_points_compressed
    assert a.points.array.tobytes() == b.points.array.tobytes()
    wkt = lambda h: [v.string for v in h.vlrs if isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr)]  # noqa: E731
    assert wkt(a.header) == wkt(b.header) != []


@pytest.mark.parametrize(
    "argv, message",
    [
        (["info", "{tmp}/missing.laz"], "file not found"),
        (["info", "{tmp}/missing.e57"], "file not found"),  # not "unknown extension": the file is missing
        (["features", "{tmp}", "{tmp}/b.laz", "-r", "1"], "no .las / .laz files in this folder"),  # a folder = tiles
        (["convert", "{tmp}/a.xyz", "{tmp}/b.las", "--ascii"], "--ascii applies to .ply output only"),
        (["convert", "{tmp}/a.xyz", "{tmp}/a.xyz"], "is the input file"),
        (["convert", "{tmp}/a.xyz", "{tmp}/nodir/b.las"], "output folder does not exist"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.e57"], "unknown file extension"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.las", "--columns", "x,y"], "no column named z"),
        # outputs are checked before any work (the model does not exist: its error would come later)
        (["features", "{tmp}/a.xyz", "{tmp}/nodir/b.las"], "output folder does not exist"),
        (["dtm", "{tmp}/a.xyz", "{tmp}/nodir/d.tif"], "output folder does not exist"),
        (["dtm", "{tmp}/a.xyz", "{tmp}/d.tif", "--classify", "-r", "1e308"], "larger than any survey"),
        (["dtm", "{tmp}/a.xyz", "{tmp}/d.tif", "--cell", "nan"], "cell must be a positive number"),  # unused, still checked
        (["ground", "{tmp}/a.xyz", "{tmp}/b.laz", "--dtm", "{tmp}/d.tif", "-r", "0"], "resolution must be a positive"),
        (["ground", "{tmp}/a.xyz", "{tmp}/b.las", "--dtm", "{tmp}/nodir/d.tif"], "output folder does not exist"),
        (["ground", "{tmp}/a.xyz", "{tmp}/b.e57"], "unknown file extension"),
        (["ground-eval", "{tmp}/a.xyz", "--reference-class", "-1"], "must be a class code 0..255"),
        (["ground-eval", "{tmp}/a.xyz", "--reference-class", "256"], "must be a class code 0..255"),
        (["segment", "{tmp}/a.xyz", "{tmp}/b.e57"], "unknown file extension"),
        (["classify", "predict", "{tmp}/a.xyz", "{tmp}/b.e57", "--model", "{tmp}/none.skops"], "unknown file extension"),
        (["classify", "predict", "{tmp}/a.xyz", "{tmp}/nodir/b.laz", "--model", "{tmp}/none.skops"],
         "output folder does not exist"),
        # a.xyz has no classes: training would fail later with another message
        (["classify", "train", "{tmp}/a.xyz", "--model", "{tmp}/nodir/m.skops"], "output folder does not exist"),
        (["classify", "evaluate", "{tmp}/a.xyz", "--out", "{tmp}/a.xyz"], "exists and is not a folder"),
        (["classify", "evaluate", "{tmp}/a.xyz", "--buffer", "-1"], "buffer must be a number of metres"),
        (["classify", "evaluate", "{tmp}/a.xyz", "-r", "1e308"], "the default buffer (twice the largest radius) is inf m"),
        # edge_share is a share (1.5 was accepted: type II 30 % on real data)
        (["ground", "{tmp}/a.xyz", "{tmp}/b.laz", "--edge-share", "1.5"], "edge_share is a share of the boundary from 0 to 1"),
        (["ground-eval", "{tmp}/a.xyz", "--edge-share", "1.5", "--json"], "edge_share is a share of the boundary from 0 to 1"),
        (["dtm", "{tmp}/a.xyz", "{tmp}/d.tif", "--classify", "--edge-share", "1.5"], "edge_share is a share"),
        # class codes are 0..255 (were accepted silently)
        (["ground", "{tmp}/a.xyz", "{tmp}/b.laz", "--ignore-classes", "256"],
         "ignore_classes must be class codes from 0 to 255, got 256"),
        (["ground", "{tmp}/a.xyz", "{tmp}/b.laz", "--ignore-classes", "7,-1"], "class codes from 0 to 255, got -1"),
        (["ground", "{tmp}/a.xyz", "{tmp}/b.laz", "--ignore-classes", "99999999999999999999999"],
         "class codes from 0 to 255, got 99999999999999999999999"),
        (["ground-eval", "{tmp}/a.xyz", "--ignore-classes", "1000000000"], "class codes from 0 to 255, got 1000000000"),
        (["dtm", "{tmp}/a.xyz", "{tmp}/d.tif", "--classify", "--ignore-classes", "256"], "class codes from 0 to 255"),
        # --precision: 1e9 tried a 4 GB line, a 23-digit value was a ValueError traceback, 100 wrote noise
        (["convert", "{tmp}/a.xyz", "{tmp}/b.xyz", "--precision", "1000000000"],
         "precision must be an integer from 0 to 17 (decimals of x, y, z), got 1000000000"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.xyz", "--precision", "99999999999999999999999"], "from 0 to 17"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.xyz", "--precision", "100"], "from 0 to 17"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.xyz", "--precision", "18"], "from 0 to 17"),
        (["convert", "{tmp}/a.xyz", "{tmp}/b.xyz", "--precision", "-1"], "from 0 to 17"),
        # an integer option beyond the numba kernel's int64 was a TypingError traceback
        (["segment", "{tmp}/a.xyz", "{tmp}/b.laz", "--min-size", "99999999999999999999999"],
         "min_size must be an integer from 1 to 10^12, got 99999999999999999999999"),
        # synth: an origin of 1e23 gave every point the same x; a density of 1e-300 wrote 0 points
        (["synth", "plane", "{tmp}/s.laz", "--origin", "1e308,0,0"], "origin coordinates must be at most 1e+09"),
        (["synth", "plane", "{tmp}/s.laz", "--origin", "0,1e23,0"], "origin coordinates must be at most 1e+09"),
        (["synth", "plane", "{tmp}/s.laz", "--rotation", "1e308,0,0,0,1,0,0,0,1"], "rotation must be a proper"),
        (["synth", "terrain", "{tmp}/s.laz", "--density", "1e-300"],
         "terrain: the scene has no points at density 1e-300; raise the density"),
        # demo: a bad seed left the empty output folder behind
        (["demo", "--out", "{tmp}/demo_bad", "--seed", "-1"], "seed must be >= 0, got -1"),
        (["demo", "--out", "{tmp}/demo_bad/sub", "--seed", "-1"], "seed must be >= 0, got -1"),
    ],
)
def test_cli_errors_in_process(tmp_path, capsys, argv, message):
    (tmp_path / "a.xyz").write_text("1 2 3\n4 5 6\n")
    rc = main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("lidarfx: error: ") and message in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.xyz"]
    assert (tmp_path / "a.xyz").read_text() == "1 2 3\n4 5 6\n"


def test_text_precision_is_0_to_17_decimals(tmp_path):
    """The library refuses it too (1e9 decimals tried a 4 GB line, 100 wrote rounding noise)."""
    from lidarfx.errors import LidarfxError

    cloud = lidarfx.PointCloud(np.array([[0.1, 2.0, 3.0], [500000.123, 5400000.456, 301.5]]))
    for bad in (18, 100, 10**9, 10**23, -1, 2.5, True):
        with pytest.raises(LidarfxError, match="precision must be an integer from 0 to 17"):
            lidarfx.write(cloud, tmp_path / "p.xyz", precision=bad)
    assert not (tmp_path / "p.xyz").exists()
    lidarfx.write(cloud, tmp_path / "p.xyz", precision=17)
    assert np.array_equal(read(tmp_path / "p.xyz").xyz, cloud.xyz)  # 17 decimals round-trip exactly
    lidarfx.write(cloud, tmp_path / "p.xyz", precision=np.int64(0))
    assert (tmp_path / "p.xyz").read_text().splitlines()[1:] == ["0 2 3", "500000 5400000 302"]


def test_cli_subprocess_exit_code_and_one_line_error(tmp_path):
    (tmp_path / "bad.laz").write_bytes(b"LASF" + bytes(100))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(
        [sys.executable, "-m", "lidarfx", "info", str(tmp_path / "bad.laz")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith("lidarfx: error: cannot read ") and "bad.laz" in proc.stderr


def test_cli_subprocess_info_json(tmp_path):
    src = real("samp41-utm.laz")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run(
        [sys.executable, "-m", "lidarfx", "info", "--json", str(src)], capture_output=True, text=True, env=env, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["points"] == 11_231
    assert {c["code"]: c["count"] for c in res["classes"]} == {0: 5_629, 2: 5_602}


def test_check_output_path(tmp_path):
    from lidarfx.errors import LidarfxError
    from lidarfx.io import check_output_path

    assert check_output_path(tmp_path / "ok.laz") == tmp_path / "ok.laz"
    (tmp_path / "d.laz").mkdir()
    with pytest.raises(LidarfxError, match="is a folder"):
        check_output_path(tmp_path / "d.laz")
    with pytest.raises(LidarfxError, match="unknown file extension"):
        check_output_path(tmp_path / "x.e57")
    with pytest.raises(LidarfxError, match="output folder does not exist"):
        check_output_path(tmp_path / "no" / "x.las")


def test_info_with_a_column_spec(tmp_path, capsys):
    """`info --columns` reads headerless text as the other commands do; the file keeps its typed name."""
    path = tmp_path / "pts.txt"
    path.write_text("1 2 3 2\n4 5 6 6\n7 8 9 2\n")
    assert main(["info", str(path), "--columns", "x,y,z,classification", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["file"] == str(path) and res["points"] == 3
    assert [(c["code"], c["count"]) for c in res["classes"]] == [(2, 2), (6, 1)]
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["classes"] is None  # col3 is no classification


def test_a_column_spec_applies_to_the_text_inputs_only(tmp_path, capsys):
    """One command can mix headerless text and LAS: `--columns` names the text file's columns and
    leaves the LAS file's fields alone; a spec that fits no input is still refused."""
    txt = tmp_path / "pts.txt"
    txt.write_text("1 2 3 2\n4 5 6 6\n7 8 9 2\n")
    las = tmp_path / "pts.laz"
    lidarfx.write(lidarfx.PointCloud(np.array([[0.0, 0, 0], [1, 1, 1]]),
                                     {"classification": np.array([6, 6], np.uint8)}), las)
    assert main(["info", str(txt), str(las), "--columns", "x,y,z,classification", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["file"] for r in res] == [str(txt), str(las)]
    assert [[(c["code"], c["count"]) for c in r["classes"]] for r in res] == [[(2, 2), (6, 1)], [(6, 2)]]
    assert main(["info", str(las), "--columns", "x,y,z,classification"]) == 2
    assert "a column spec applies only to text and .npy files" in capsys.readouterr().err
