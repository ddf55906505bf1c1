"""The unit rule (docs/conventions.md): lengths are metres, converted for files whose CRS is in feet;
the CRS module; the warning when most of a computed feature is NaN."""
from __future__ import annotations

import json
import re
import warnings

import laspy
import numpy as np
import pytest

import lidarfx
from lidarfx.cli import main
from lidarfx.features import compute_features

US_FT = 1200 / 3937
FOOT_WKT = (
    'PROJCS["NAD83 / test (ftUS)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",'
    'SPHEROID["GRS 1980",6378137,298.257222101]],UNIT["degree",0.0174532925199433]],'
    'PROJECTION["Transverse_Mercator"],UNIT["US survey foot",0.3048006096012192]]'
)


def _write_las(path, xyz, wkt=None, scale=1e-4):
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales = np.full(3, scale)
    header.offsets = np.floor(xyz.min(axis=0))
    if wkt:
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.write(path)
    return path


def _scene(seed=0, n=6000):
    """A box of scattered points over a noisy plane (metres)."""
    rng = np.random.default_rng(seed)
    plane = np.column_stack([rng.uniform(0, 8, n), rng.uniform(0, 8, n), rng.normal(0, 0.01, n)])
    box = rng.uniform([2, 2, 0], [4, 4, 2], (n // 3, 3))
    return np.vstack([plane, box]) + [1000.0, 2000.0, 50.0]


@pytest.fixture(scope="module")
def feet_and_metres(tmp_path_factory):
    """The same scene in a LAS in US survey feet (with its CRS) and in memory in metres."""
    folder = tmp_path_factory.mktemp("units")
    path = _write_las(folder / "feet.las", _scene() / US_FT, FOOT_WKT)
    feet = lidarfx.read(path)
    metres = lidarfx.PointCloud(feet.xyz * US_FT, {})
    return path, feet, metres


def test_crs_module_is_the_one_place_for_the_unit(feet_and_metres):
    from lidarfx import crs
    from lidarfx.classify.pipeline import unit_to_metre
    from lidarfx.ground.dtm import cloud_crs
    from lidarfx.io.las import crs_info

    _, feet, metres = feet_and_metres
    assert crs.unit_to_metre(feet) == pytest.approx(US_FT) and crs.unit_to_metre(metres) == 1.0
    assert unit_to_metre is crs.unit_to_metre and cloud_crs is crs.cloud_crs and crs_info is crs.crs_info
    assert crs.crs_info(feet.header)["linear_unit"] == "US survey foot"
    assert crs.length_to_units(feet, 1.0) == pytest.approx(1 / US_FT)
    assert crs.length_to_units(feet, 1.0, units="native") == 1.0 and crs.length_to_units(feet, None) is None
    assert crs.unit_name(feet) == "US survey ft" and crs.unit_name(metres) == "m"


def test_features_of_a_feet_file_equal_the_metre_cloud(feet_and_metres, tmp_path, capsys):
    """Radii are metres: a US-feet file gives the features of the same cloud in metres."""
    path, feet, metres = feet_and_metres
    names = ["planarity", "linearity", "sphericity", "verticality", "omnivariance"]
    ref = compute_features(metres, names, radii=[0.3, 0.6])
    got = compute_features(feet, names, radii=[0.3, 0.6])
    for name in names:
        for sfx in ("_r0.30", "_r0.60"):  # the suffix names the radius in metres
            a, b = np.asarray(got[name + sfx]), np.asarray(ref[name + sfx])
            assert np.array_equal(np.isnan(a), np.isnan(b)), name + sfx
            np.testing.assert_allclose(a, b, atol=2e-4, equal_nan=True)
    # the command line: -r 0.3 is metres too
    out = tmp_path / "fx.las"
    assert main(["features", str(path), str(out), "-r", "0.3", "-f", ",".join(names), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["units"]["coordinates"] == "US survey ft" and summary["warnings"] == []
    las = laspy.read(out)
    one = compute_features(metres, names, radius=0.3)
    for name in names:
        np.testing.assert_allclose(np.asarray(las[name]), one[name], atol=2e-4, equal_nan=True)


def test_thin_cell_of_a_feet_file_is_metres(feet_and_metres, tmp_path, capsys):
    """--cell 0.5 keeps one point per 0.5 m cell of a US-feet file (not per 0.5 ft)."""
    path, feet, metres = feet_and_metres
    mpath = tmp_path / "metres.npz"
    lidarfx.write(metres, mpath)
    assert main(["thin", str(mpath), str(tmp_path / "m.npz"), "--cell", "0.5", "--json"]) == 0
    m = json.loads(capsys.readouterr().out)
    assert main(["thin", str(path), str(tmp_path / "f.las"), "--cell", "0.5", "--json"]) == 0
    f = json.loads(capsys.readouterr().out)
    assert abs(f["kept"] - m["kept"]) <= 2  # the same cells (a point on a cell face may round to the other)
    assert f["kept"] < 0.5 * f["points"]
    assert f["cell"] == 0.5 and f["units"]["coordinates"] == "US survey ft"
    thin_ft = lidarfx.thin.thin_cloud(feet, 0.5)
    assert len(thin_ft) == f["kept"]


def test_segment_lengths_of_a_feet_file_are_metres(feet_and_metres):
    """segment_planes: --normal-radius, --max-distance, --growing-radius, --min-width in metres."""
    _, feet, metres = feet_and_metres
    kw = dict(normal_radius=0.3, max_distance=0.05, growing_radius=0.3, min_size=50, min_width=0.5)
    a = lidarfx.segment.segment_planes(feet, **kw)
    b = lidarfx.segment.segment_planes(metres, **kw)
    assert a.meta["segmentation"]["segments"] == b.meta["segmentation"]["segments"] >= 1
    assert np.mean(a["segment_id"] == b["segment_id"]) > 0.99
    ta, tb = lidarfx.segment.segments_table(a)[0], lidarfx.segment.segments_table(b)[0]
    assert ta["rms"] == pytest.approx(tb["rms"], rel=1e-3) and ta["area"] == pytest.approx(tb["area"], rel=1e-3)


@pytest.fixture(scope="module")
def sparse_las(tmp_path_factory):
    """About one point per m² over 40 m x 40 m of gently rolling ground (metres, no CRS)."""
    rng = np.random.default_rng(3)
    n = 1600
    xy = rng.uniform(0, 40, (n, 2))
    z = 0.3 * np.sin(xy[:, 0] / 5) + rng.normal(0, 0.02, n)
    return _write_las(tmp_path_factory.mktemp("sparse") / "sparse.las", np.column_stack([xy, z]) + [500, 600, 10])


def test_nan_warning_names_the_cause_and_a_radius_that_works(sparse_las, tmp_path, capsys):
    out = tmp_path / "a.las"
    assert main(["features", str(sparse_las), str(out), "-r", "0.2", "-f", "eigen", "--json", "-q"]) == 0
    cap = capsys.readouterr()
    summary = json.loads(cap.out)
    warn = [line for line in cap.err.splitlines() if line.startswith("lidarfx: warning: ")]
    assert len(warn) == 1 and summary["warnings"] == [warn[0][len("lidarfx: warning: "):]]
    text = summary["warnings"][0]
    assert summary["nan_share"]["planarity"] > 0.5
    assert "NaN for" in text and "below the point spacing" in text and "fewer than 3 points" in text  # r < spacing
    spacing = float(re.search(r"point spacing \(([0-9.]+) m", text).group(1))
    assert 0.2 < spacing < 1.0  # about 1 / (2 sqrt(density)) for random points
    radius = re.search(r"-r ([0-9.]+)", text).group(1)
    assert float(radius) > spacing
    # that radius indeed works
    assert main(["features", str(sparse_las), str(tmp_path / "b.las"), "-r", radius, "-f", "eigen", "--json",
                 "-q"]) == 0
    cap = capsys.readouterr()
    fixed = json.loads(cap.out)
    assert max(fixed["nan_share"].values()) < 0.5
    assert fixed["warnings"] == [] and "lidarfx: warning" not in cap.err


def test_nan_warning_in_python(sparse_las):
    cloud = lidarfx.read(sparse_las)
    with pytest.warns(lidarfx.errors.LidarfxWarning, match="planarity is NaN .* point spacing"):
        out = compute_features(cloud, "planarity", radius=0.4)
    assert "below the point spacing" in out.meta["feature_warnings"][0]
    # a level plane's aspect is NaN by design: no warning
    flat = lidarfx.PointCloud(np.column_stack([cloud.xyz[:, :2], np.zeros(len(cloud))]), {})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(compute_features(flat, "aspect", radius=3.0)["aspect"]).all()


def test_no_warning_on_a_normal_run(feet_and_metres, tmp_path, capsys):
    path, _, _ = feet_and_metres
    assert main(["features", str(path), str(tmp_path / "n.las"), "-r", "0.5", "-f", "eigen,plane,curvature",
                 "--json"]) == 0
    cap = capsys.readouterr()
    summary = json.loads(cap.out)
    assert summary["warnings"] == [] and "lidarfx: warning" not in cap.err
    assert max(summary["nan_share"].values()) < 0.5


def test_chunked_features_of_a_feet_file_are_metres(feet_and_metres, tmp_path, capsys):
    """In chunks too: --chunk-size, --buffer and -r are metres (the chunks' features equal the
    in-memory run's, the summary gives the sizes in metres)."""
    path, feet, _ = feet_and_metres
    out = tmp_path / "chunked.las"
    assert main(["features", str(path), str(out), "-r", "0.3", "-r", "0.6", "-f", "planarity,linearity",
                 "--chunk-size", "3", "--buffer", "0.6", "--workers", "1", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["chunk_size"] == pytest.approx(3.0) and summary["buffer"] == pytest.approx(0.6)
    assert summary["chunks"] >= 9  # 3 m chunks over 8 m (not 3 ft)
    las = laspy.read(out)
    ref = compute_features(feet, "planarity,linearity", radii=[0.3, 0.6])
    for name in ("planarity_r0.30", "linearity_r0.60"):
        np.testing.assert_array_equal(np.asarray(las[name]), ref[name])
    assert main(["features", str(path), str(tmp_path / "narrow.las"), "-r", "0.6", "-f", "planarity",
                 "--chunk-size", "3", "--buffer", "0.5", "--workers", "1", "-q"]) == 2
    assert "--buffer 0.5 m is narrower than the 0.6 m" in capsys.readouterr().err


def test_line_tables_of_a_feet_file_are_metres(feet_and_metres, tmp_path):
    """Vector outputs keep the file's coordinates but give lengths and rms in metres, and say so."""
    import csv

    from lidarfx.crs import cloud_crs
    from lidarfx.vector import Polyline, export_lines

    path, feet, _ = feet_and_metres
    line = Polyline(np.array([[0.0, 0, 0], [3000.0, 4000.0, 0]]), support=10, rms=1.0, kind="edge")  # 5000 ft
    crs = cloud_crs(feet)
    out = export_lines([line], geojson=tmp_path / "l.geojson", csv=tmp_path / "l.csv", json=tmp_path / "l.json",
                       crs=crs)
    row = next(csv.DictReader(open(out["csv"])))
    assert float(row["length"]) == pytest.approx(5000 * US_FT, abs=1e-3)
    assert float(row["rms"]) == pytest.approx(US_FT, abs=1e-4)
    g = json.load(open(out["geojson"]))
    assert g["features"][0]["geometry"]["coordinates"][1][:2] == [3000.0, 4000.0]  # coordinates stay feet
    assert g["features"][0]["properties"]["length"] == pytest.approx(5000 * US_FT, abs=1e-3)
    assert g["lidarfx"]["units"]["lengths"] == "m" and g["lidarfx"]["units"]["coordinates"] == "US survey ft"
    assert json.load(open(out["json"]))["lines"][0]["length_2d"] == pytest.approx(5000 * US_FT, abs=1e-3)
    # a metric file: unchanged, no units entry
    out = export_lines([line], geojson=tmp_path / "m.geojson", crs={"epsg": 25832, "unit_to_metre": 1.0})
    g = json.load(open(out["geojson"]))
    assert g["features"][0]["properties"]["length"] == 5000.0 and "lidarfx" not in g


def test_the_scale_bar_of_a_feet_file_is_metres(feet_and_metres, tmp_path):
    """The picture of the same scene in feet and in metres gets the same scale bar, in metres."""
    from lidarfx.render import render_picture

    _, feet, metres = feet_and_metres
    a = render_picture(feet, tmp_path / "f.png", size="300x200", progress=False)
    b = render_picture(metres, tmp_path / "m.png", size="300x200", progress=False)
    assert a[1]["scale_bar_m"] == b[1]["scale_bar_m"]
