"""Reading, writing and summarising point clouds (lidarfx.io)."""
from __future__ import annotations

import hashlib
from pathlib import Path

import laspy
import numpy as np
import pytest

from lidarfx import LidarfxError, PointCloud
from lidarfx.io import info, las as las_io, read, write

REAL = (Path(__file__).parents[1] / ".." / "shared" / "data" / "real").resolve()

REAL_LAS = [
    "12AN2_20.laz",  # 1.4 PF7
    "AHN3.laz",  # 1.2 PF3
    "MixedConifer.laz",  # 1.2 PF1 + treeID (float64 extra dim, no_data)
    "TO_core_last_zoom.laz",  # 1.0 PF1
    "Topography.laz",
    "autzen_trim.laz",  # GeoTIFF + WKT, feet
    "crop_1.laz",  # 1.4 PF6 + ScanChannel (uint8 extra dim)
    "file_with_both_wkt_and_geotiff_vlrs.las",  # 1.4 PF6, US feet
    "fusa.laz",  # 1.1 PF1
    "lake.laz",
    "lone-star.laz",
    "plane.laz",
    "pont.laz",
    "samp11-utm.laz",  # 1.2 PF0
    "samp21-utm.laz",
    "samp23-utm.laz",
    "samp31-utm.laz",
    "samp41-utm.laz",
    "samp51-utm.laz",
    "samp53-utm.laz",
    "samp61-utm.laz",
    "sample_c.las",
    "test_data_77050_627755_LA93_IGN69.laz",  # 1.4 PF8
    "test_data_77055_627755_LA93_IGN69.laz",
    "test_data_77060_627755_LA93_IGN69.laz",
    "warsaw_small.las",
]


def real(name: str) -> Path:
    path = REAL / name
    if not path.exists():
        pytest.skip(f"real data not found: {path}")
    return path


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def vlr_payloads(vlrs) -> list[tuple[str, int, str, bytes]]:
    """(user_id, record_id, description, payload) of every VLR except the LASzip one."""
    out = []
    for v in vlrs or []:
        if isinstance(v, laspy.vlrs.known.LasZipVlr):
            continue
        data = v.record_data_bytes() if hasattr(v, "record_data_bytes") else v.record_data
        out.append((v.user_id, v.record_id, v.description, bytes(data)))
    return out


def small_cloud(n: int = 500, seed: int = 0) -> PointCloud:
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, 50, (n, 3)) + [500_000.0, 5_400_000.0, 100.0]
    xyz = np.round(xyz, 3)
    return PointCloud(
        xyz,
        {
            "intensity": rng.integers(0, 65535, n).astype(np.uint16),
            "classification": rng.choice([1, 2, 5, 6], n).astype(np.uint8),
            "planarity": rng.random(n),  # float64
            "linearity": rng.random(n).astype(np.float32),
            "segment_id": rng.integers(-1, 40, n).astype(np.int64),
            "overhang": rng.random(n) > 0.5,
        },
    )


# --------------------------------------------------------------------- LAS
@pytest.mark.parametrize("name", REAL_LAS)
def test_las_read_matches_laspy(name):
    path = real(name)
    ref = laspy.read(path)
    cloud = read(path)
    assert len(cloud) == ref.header.point_count
    assert np.array_equal(cloud.xyz, np.column_stack([ref.x, ref.y, ref.z]))
    assert isinstance(cloud.header, laspy.LasHeader)
    assert cloud.header.point_format.id == ref.point_format.id
    dims = [d for d in ref.point_format.dimension_names if d not in ("X", "Y", "Z")]
    assert cloud.names == dims
    for dim in dims:
        expected = np.asarray(ref[dim])
        assert cloud[dim].dtype == expected.dtype, dim
        assert np.array_equal(cloud[dim], expected), dim
    assert cloud.meta["source"] == str(path)
    assert cloud.meta["format"] == "las"


@pytest.mark.parametrize("name", REAL_LAS)
def test_las_round_trip_is_bit_exact(name, tmp_path):
    path = real(name)
    cloud = read(path)
    out = tmp_path / f"copy{path.suffix}"
    write(cloud, out)
    a, b = laspy.read(path), laspy.read(out)
    # Same point records, byte for byte (every standard field and extra dim, raw X/Y/Z).
    assert a.points.array.dtype == b.points.array.dtype
    assert a.points.array.tobytes() == b.points.array.tobytes()
    assert np.array_equal(a.X, b.X) and np.array_equal(a.Y, b.Y) and np.array_equal(a.Z, b.Z)
    # Header pass-through.
    assert b.header.point_format.id == a.header.point_format.id
    expected_version = "1.1" if str(a.header.version) == "1.0" else str(a.header.version)
    assert str(b.header.version) == expected_version
    assert np.array_equal(a.header.scales, b.header.scales)
    assert np.array_equal(a.header.offsets, b.header.offsets)
    assert a.header.system_identifier == b.header.system_identifier
    assert a.header.generating_software == b.header.generating_software
    assert list(a.point_format.extra_dimension_names) == list(b.point_format.extra_dimension_names)
    # CRS and every other VLR / EVLR payload, byte for byte (extra-bytes VLR included).
    assert vlr_payloads(a.header.vlrs) == vlr_payloads(b.header.vlrs)
    assert vlr_payloads(a.header.evlrs) == vlr_payloads(b.header.evlrs)
    # And lidarfx reads back the same cloud.
    again = read(out)
    assert np.array_equal(again.xyz, cloud.xyz)
    assert again.names == cloud.names
    for k in cloud.names:
        assert again[k].dtype == cloud[k].dtype and np.array_equal(again[k], cloud[k]), k


def test_las_chunked_read_and_write_match(tmp_path, monkeypatch):
    """Multi-chunk, multi-block paths give the same bytes as one chunk."""
    path = real("crop_1.laz")
    whole = read(path)
    monkeypatch.setattr(las_io, "CHUNK_POINTS", 10_007)
    monkeypatch.setattr(las_io, "_BLOCK_POINTS", 1_001)
    chunked = read(path, progress=True)
    assert np.array_equal(whole.xyz, chunked.xyz)
    assert all(np.array_equal(whole[k], chunked[k]) for k in whole.names)
    write(chunked, tmp_path / "c.laz", progress=True)
    a, b = laspy.read(path), laspy.read(tmp_path / "c.laz")
    assert a.points.array.tobytes() == b.points.array.tobytes()
    assert vlr_payloads(a.header.vlrs) == vlr_payloads(b.header.vlrs)


def test_las_to_laz_to_las_keeps_records_and_crs(tmp_path):
    path = real("file_with_both_wkt_and_geotiff_vlrs.las")
    write(read(path), tmp_path / "a.laz")
    assert laspy.open(tmp_path / "a.laz").header.are_points_compressed
    write(read(tmp_path / "a.laz"), tmp_path / "b.las")
    a, b = laspy.read(path), laspy.read(tmp_path / "b.las")
    assert a.points.array.tobytes() == b.points.array.tobytes()
    assert vlr_payloads(a.header.vlrs) == vlr_payloads(b.header.vlrs)
    kinds = [type(v).__name__ for v in b.header.vlrs]
    assert "WktCoordinateSystemVlr" in kinds and "GeoKeyDirectoryVlr" in kinds


def test_las_evlrs_pass_through(tmp_path):
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales = np.array([0.01, 0.01, 0.01])
    src = laspy.LasData(header)
    src.x = np.array([1.0, 2.0, 3.5])
    src.y = np.array([4.0, 5.0, 6.25])
    src.z = np.array([7.0, 8.0, 9.0])
    src.classification = np.array([2, 6, 9], dtype=np.uint8)
    payload = bytes(range(200)) * 3
    src.evlrs = laspy.vlrs.vlrlist.VLRList([laspy.VLR("lidarfx_test", 42, "an EVLR", payload)])
    src.write(tmp_path / "evlr.las")
    write(read(tmp_path / "evlr.las"), tmp_path / "out.las")
    back = laspy.read(tmp_path / "out.las")
    assert [(v.user_id, v.record_id, bytes(v.record_data)) for v in back.evlrs] == [("lidarfx_test", 42, payload)]
    assert np.array_equal(back.classification, [2, 6, 9])


def test_scaled_array_and_no_data_extra_dims(tmp_path):
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams("height", "i4", scales=np.array([0.01]), offsets=np.array([100.0])),
            laspy.ExtraBytesParams("normal", "3f4"),
            laspy.ExtraBytesParams("amp", "u2", no_data=[65535]),
        ]
    )
    src = laspy.LasData(header)
    src.x, src.y, src.z = np.arange(5.0), np.arange(5.0) * 2, np.ones(5)
    src["height"] = np.array([100.5, 101.25, 99.99, 100.0, 120.0])
    src["normal"] = np.arange(15, dtype=np.float32).reshape(5, 3)
    src["amp"] = np.array([1, 2, 65535, 4, 5], dtype=np.uint16)
    src.write(tmp_path / "ex.las")
    cloud = read(tmp_path / "ex.las")
    assert cloud.names[-5:] == ["height", "normal_0", "normal_1", "normal_2", "amp"]
    assert cloud["height"].dtype == np.float64 and np.allclose(cloud["height"], [100.5, 101.25, 99.99, 100.0, 120.0])
    assert cloud["normal_2"].tolist() == [2, 5, 8, 11, 14] and cloud["amp"].dtype == np.uint16
    write(cloud, tmp_path / "out.las")
    back = laspy.read(tmp_path / "out.las")
    assert back.points.array.tobytes() == laspy.read(tmp_path / "ex.las").points.array.tobytes()
    stats = {s.format_name(): (s.min, s.max) for s in back.header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs}
    assert np.allclose(stats["height"], ([99.99], [120.0]))  # min/max of the data (scaled)
    assert [v.tolist() for v in stats["amp"]] == [[1], [5]]  # the no_data value 65535 is left out
    assert stats["normal"][0].tolist() == [0, 1, 2] and stats["normal"][1].tolist() == [12, 13, 14]


def test_new_cloud_gets_las14_pf6_and_typed_extra_dims(tmp_path):
    cloud = small_cloud()
    out = tmp_path / "new.laz"
    write(cloud, out)
    ref = laspy.read(out)  # plain laspy, as CloudCompare / PDAL would see it
    assert str(ref.header.version) == "1.4"
    assert ref.header.point_format.id == 6
    assert np.allclose(ref.header.scales, 0.001)
    assert np.array_equal(ref.header.offsets, np.floor(cloud.xyz.min(axis=0)))
    assert np.array_equal(np.asarray(ref.X), np.rint((cloud.x - ref.header.offsets[0]) / 0.001).astype(np.int32))
    assert np.abs(np.column_stack([ref.x, ref.y, ref.z]) - cloud.xyz).max() <= 0.0005
    assert np.array_equal(ref.intensity, cloud["intensity"])
    assert np.array_equal(ref.classification, cloud["classification"])
    extra = {d.name: d.dtype for d in ref.point_format.extra_dimensions}
    assert extra == {
        "planarity": np.dtype(np.float32),
        "linearity": np.dtype(np.float32),
        "segment_id": np.dtype(np.int32),
        "overhang": np.dtype(np.int32),
    }
    assert np.array_equal(ref["planarity"], cloud["planarity"].astype(np.float32))
    assert np.array_equal(ref["linearity"], cloud["linearity"])
    assert np.array_equal(ref["segment_id"], cloud["segment_id"])
    assert np.array_equal(ref["overhang"], cloud["overhang"].astype(np.int32))
    # The standard LAS 1.4 extra-bytes VLR describes them (what CloudCompare / PDAL read).
    eb = ref.header.vlrs.get("ExtraBytesVlr")[0]
    assert [s.format_name() for s in eb.extra_bytes_structs] == ["planarity", "linearity", "segment_id", "overhang"]
    assert [s.data_type for s in eb.extra_bytes_structs] == [9, 9, 6, 6]  # float, float, long, long


def test_rgb_selects_point_format_7(tmp_path):
    cloud = small_cloud(50)
    for c in ("red", "green", "blue"):
        cloud[c] = np.arange(50, dtype=np.uint16) * 1000
    write(cloud, tmp_path / "rgb.las")
    ref = laspy.read(tmp_path / "rgb.las")
    assert ref.header.point_format.id == 7
    assert np.array_equal(ref.green, cloud["green"])
    assert "red" not in list(ref.point_format.extra_dimension_names)


def test_source_header_gets_new_features_and_keeps_its_extra_dims(tmp_path):
    path = real("MixedConifer.laz")
    cloud = read(path)
    cloud["planarity"] = np.linspace(0, 1, len(cloud))
    cloud["segment_id"] = np.arange(len(cloud)) % 7 - 1
    write(cloud, tmp_path / "feat.laz")
    src, ref = laspy.read(path), laspy.read(tmp_path / "feat.laz")
    assert ref.header.point_format.id == 1 and str(ref.header.version) == "1.2"
    types = {d.name: d.dtype for d in ref.point_format.extra_dimensions}
    assert types == {"treeID": np.dtype(np.float64), "planarity": np.dtype(np.float32), "segment_id": np.dtype(np.int32)}
    assert np.array_equal(ref["treeID"], src["treeID"])
    assert np.array_equal(ref["segment_id"], cloud["segment_id"])
    assert np.array_equal(ref.X, src.X) and np.array_equal(ref.classification, src.classification)
    geokeys = lambda h: [p for p in vlr_payloads(h.vlrs) if p[1] == 34735]  # noqa: E731
    assert geokeys(ref.header) == geokeys(src.header) != []


def test_adding_rgb_widens_point_format_in_family(tmp_path):
    cloud = read(real("samp11-utm.laz"))  # LAS 1.2, point format 0
    cloud["red"] = np.full(len(cloud), 65535, dtype=np.uint16)
    cloud["green"] = np.zeros(len(cloud), dtype=np.uint16)
    cloud["blue"] = np.full(len(cloud), 300, dtype=np.uint16)
    write(cloud, tmp_path / "rgb.laz")
    ref = laspy.read(tmp_path / "rgb.laz")
    assert ref.header.point_format.id == 2 and str(ref.header.version) == "1.2"
    assert np.array_equal(ref.blue, cloud["blue"])
    assert list(ref.point_format.extra_dimension_names) == []


def test_dropped_attribute_drops_source_extra_dim(tmp_path):
    cloud = read(real("crop_1.laz"))
    del cloud["ScanChannel"]
    write(cloud, tmp_path / "noscan.laz")
    ref = laspy.read(tmp_path / "noscan.laz")
    assert list(ref.point_format.extra_dimension_names) == []
    assert np.array_equal(np.asarray(ref.return_number), cloud["return_number"])


def test_points_moved_far_get_new_offsets(tmp_path):
    cloud = read(real("samp21-utm.laz"))  # scale 0.01, offset 500000
    cloud.xyz[:, 0] += 40_000_000.0  # no longer fits int32 with the old offset
    write(cloud, tmp_path / "far.las")
    ref = laspy.read(tmp_path / "far.las")
    assert ref.header.offsets[0] == np.floor(cloud.x.min())
    assert np.abs(np.asarray(ref.x) - cloud.x).max() <= 0.005 + 1e-6


def test_scale_option(tmp_path):
    cloud = small_cloud(100)
    write(cloud, tmp_path / "s.las", scale=0.01)
    ref = laspy.read(tmp_path / "s.las")
    assert np.allclose(ref.header.scales, 0.01)
    assert np.abs(np.asarray(ref.x) - cloud.x).max() <= 0.005 + 1e-6


@pytest.mark.parametrize(
    "name, values, message",
    [
        ("classification", np.full(10, 300), "classification"),
        ("intensity", np.full(10, 1.5), "fractional"),
        ("return_number", np.full(10, 20, dtype=np.uint8), "return_number"),
        ("gps_time", np.full(10, "x"), "dtype"),
    ],
)
def test_standard_field_values_must_fit(tmp_path, name, values, message):
    cloud = PointCloud(np.random.default_rng(1).random((10, 3)), {name: values})
    with pytest.raises(LidarfxError, match=message):
        write(cloud, tmp_path / "bad.las")
    assert list(tmp_path.iterdir()) == []  # no partial output


def test_legacy_point_format_rejects_class_above_31(tmp_path):
    cloud = read(real("samp41-utm.laz"))
    cloud["classification"] = np.full(len(cloud), 64, dtype=np.uint8)
    with pytest.raises(LidarfxError, match=r"0\.\.31"):
        write(cloud, tmp_path / "c64.laz")
    write(cloud, tmp_path / "c64.laz", point_format=6)
    assert np.all(laspy.read(tmp_path / "c64.laz").classification == 64)


def test_long_extra_dim_name_is_rejected(tmp_path):
    cloud = PointCloud(np.zeros((3, 3)), {"a" * 33: np.zeros(3)})
    with pytest.raises(LidarfxError, match="at most 32"):
        write(cloud, tmp_path / "long.las")
    cloud = PointCloud(np.zeros((3, 3)), {"a" * 32: np.arange(3.0)})
    write(cloud, tmp_path / "ok.las")
    assert np.array_equal(laspy.read(tmp_path / "ok.las")["a" * 32], [0, 1, 2])


def test_attribute_names_clashing_with_the_record_are_rejected(tmp_path):
    for name in ("X", "bit_fields"):
        with pytest.raises(LidarfxError, match=name):
            write(PointCloud(np.zeros((2, 3)), {name: np.zeros(2)}), tmp_path / "clash.las")


def test_nan_coordinates_are_rejected(tmp_path):
    cloud = PointCloud([[0, 0, 0], [np.nan, 1, 1]])
    with pytest.raises(LidarfxError, match="NaN"):
        write(cloud, tmp_path / "nan.las")


def test_empty_cloud_round_trip(tmp_path):
    write(PointCloud(np.empty((0, 3)), {"planarity": np.empty(0)}), tmp_path / "empty.laz")
    back = read(tmp_path / "empty.laz")
    assert len(back) == 0 and back["planarity"].dtype == np.float32


# -------------------------------------------------------------------- info
def test_info_on_feet_file_converts_density_to_metres():
    path = real("file_with_both_wkt_and_geotiff_vlrs.las")
    ref = laspy.read(path)
    res = info(path)
    assert res["points"] == 25_408
    assert res["las"]["version"] == "1.4" and res["las"]["point_format"] == 6
    crs = res["crs"]
    assert crs["linear_unit"] == "Foot_US" and crs["unit_to_metre"] == pytest.approx(0.30480060960121924)
    assert crs["epsg"] == 32104 and crs["sources"] == ["wkt", "geotiff"]
    assert crs["wkt"].startswith('PROJCS["NAD83_2011_Nebraska_ft"')
    f = crs["unit_to_metre"]
    area_m2 = (ref.x.max() - ref.x.min()) * (ref.y.max() - ref.y.min()) * f * f
    assert res["density"]["per_m2_bbox"] == pytest.approx(len(ref.x) / area_m2)
    cells = np.unique(np.column_stack([np.floor(ref.x / (1 / f)), np.floor(ref.y / (1 / f))]), axis=0)
    assert res["density"]["occupied_cells"] == len(cells)
    assert res["density"]["unit_assumed"] is False


@pytest.mark.parametrize(
    "name, epsg, unit",
    [("crop_1.laz", 2154, "metre"), ("samp11-utm.laz", 32632, "metre"), ("autzen_trim.laz", None, "foot"), ("lake.laz", None, None)],
)
def test_info_crs(name, epsg, unit):
    crs = info(real(name))["crs"]
    if unit is None:
        assert crs is None
    else:
        assert crs["epsg"] == epsg and crs["linear_unit"] == unit


WKT2_FEET = (
    'PROJCRS["WGS 84 / UTM zone 32N (ftUS)",BASEGEOGCRS["WGS 84",DATUM["World Geodetic System 1984",'
    'ELLIPSOID["WGS 84",6378137,298.257223563,LENGTHUNIT["metre",1]]],ANGLEUNIT["degree",0.0174532925199433]],'
    'CONVERSION["UTM zone 32N",METHOD["Transverse Mercator",ID["EPSG",9807]],'
    'PARAMETER["False easting",500000,LENGTHUNIT["metre",1]]],CS[Cartesian,2],'
    'AXIS["(E)",east,ORDER[1],LENGTHUNIT["US survey foot",0.304800609601219]],'
    'AXIS["(N)",north,ORDER[2],LENGTHUNIT["US survey foot",0.304800609601219]],ID["EPSG",32632]]'
)
COMPOUND = (
    'COMPD_CS["RGF93 / Lambert-93 + NGF-IGN69 height",PROJCS["RGF93 / Lambert-93",GEOGCS["RGF93",'
    'DATUM["RGF93",SPHEROID["GRS 1980",6378137,298.257222101]],UNIT["degree",0.0174532925199433]],'
    'PROJECTION["Lambert_Conformal_Conic_2SP"],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AUTHORITY["EPSG","2154"]],'
    'VERT_CS["NGF-IGN69 height",VERT_DATUM["NGF-IGN69",2005],UNIT["metre",1]],AUTHORITY["EPSG","5698"]]'
)
GEOGRAPHIC = 'GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],UNIT["degree",0.0174532925199433],AUTHORITY["EPSG","4326"]]'


@pytest.mark.parametrize(
    "wkt, epsg, unit, factor",
    [(WKT2_FEET, 32632, "US survey foot", 0.304800609601219), (COMPOUND, 5698, "metre", 1.0), (GEOGRAPHIC, 4326, None, None)],
)
def test_info_crs_from_wkt_variants(tmp_path, wkt, epsg, unit, factor):
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.array([0.0, 10.0]), np.array([0.0, 10.0]), np.zeros(2)
    las.write(tmp_path / "crs.las")
    res = info(tmp_path / "crs.las")
    crs = res["crs"]
    assert (crs["epsg"], crs["linear_unit"], crs["unit_to_metre"]) == (epsg, unit, factor)
    assert crs["geographic"] is (unit is None)
    if unit is None:
        assert res["density"] is None
    else:
        assert res["density"]["per_m2_bbox"] == pytest.approx(2 / (10 * factor) ** 2)


def test_info_on_cloud_counts_and_density():
    g = (np.arange(20) + 0.5) * 0.5  # 20 x 20 points, 0.5 m apart, in a 10 m x 10 m square
    x, y = np.meshgrid(g, g)
    xyz = np.column_stack([x.ravel(), y.ravel(), np.zeros(400)])
    cls = np.where(xyz[:, 0] < 5, 2, 6).astype(np.uint8)
    res = info(PointCloud(xyz, {"classification": cls, "return_number": np.ones(400, np.uint8)}))
    assert res["points"] == 400
    assert res["bounds"] == {"min": [0.25, 0.25, 0.0], "max": [9.75, 9.75, 0.0]}
    assert res["density"]["occupied_cells"] == 100
    assert res["density"]["per_m2_occupied_cells"] == 4.0
    assert res["density"]["per_m2_bbox"] == pytest.approx(400 / 9.5**2)
    assert res["classes"] == [
        {"code": 2, "name": "ground", "count": 200},
        {"code": 6, "name": "building", "count": 200},
    ]
    assert res["returns"] == {"return_number": {"1": 400}}
    assert res["attributes"] == {"classification": "uint8", "return_number": "uint8"}
    assert res["crs"] is None and res["las"] is None


def test_info_measured_density_leaves_out_virtual_withheld_synthetic():
    g = (np.arange(20) + 0.5) * 0.5  # 20 x 20 points, 0.5 m apart: 4 per occupied 1 m cell
    x, y = np.meshgrid(g, g)
    xyz = np.column_stack([x.ravel(), y.ravel(), np.zeros(400)])
    rn = np.where(xyz[:, 0] < 5, 1, 0).astype(np.uint8)  # the right half virtual (return number 0)
    withheld = np.zeros(400, np.uint8)
    withheld[(xyz[:, 0] < 1) & (xyz[:, 1] < 1)] = 1  # one 1 m cell's 4 points
    d = info(PointCloud(xyz, {"return_number": rn, "withheld": withheld}))["density"]
    assert d["per_m2_occupied_cells"] == 4.0  # every point
    assert d["measured"] == {"points": 196, "occupied_cells": 49, "per_m2_occupied_cells": 4.0}
    # nothing to leave out, or return numbers all 0 (not recorded): no second figure
    assert info(PointCloud(xyz, {"return_number": np.ones(400, np.uint8)}))["density"]["measured"] is None
    assert info(PointCloud(xyz, {"return_number": np.zeros(400, np.uint8)}))["density"]["measured"] is None
    # the same points as the classifier's usable points
    from lidarfx.classify import usable_mask

    cloud = PointCloud(xyz, {"return_number": rn, "withheld": withheld})
    assert d["measured"]["points"] == usable_mask(cloud).sum()


def test_info_streams_las_in_chunks(monkeypatch):
    from lidarfx.classify import usable_mask

    path = real("pont.laz")
    whole = info(path)
    monkeypatch.setattr(las_io, "CHUNK_POINTS", 9_999)
    assert info(path) == whole
    # IGN virtual points (class 66, return number 0) fill half the area: 26 pts/m² over all, 52 measured
    assert whole["density"]["measured"]["points"] == usable_mask(read(path)).sum() == 225_576
    assert whole["density"]["measured"]["per_m2_occupied_cells"] == pytest.approx(52.18, abs=0.01)


# --------------------------------------------------------------------- PLY
@pytest.mark.parametrize("ascii_", [False, True])
def test_ply_round_trip(tmp_path, ascii_):
    cloud = small_cloud(200)
    cloud["red"] = np.arange(200, dtype=np.uint8)
    write(cloud, tmp_path / "a.ply", ascii=ascii_)
    head = (tmp_path / "a.ply").read_bytes()[:200]
    assert (b"format ascii 1.0" in head) == ascii_
    assert (b"format binary_little_endian 1.0" in head) != ascii_
    back = read(tmp_path / "a.ply")
    assert np.array_equal(back.xyz, cloud.xyz)
    assert back.names == cloud.names
    for k in cloud.names:
        want = cloud[k]
        if want.dtype == np.int64:
            want = want.astype(np.int32)
        elif want.dtype == bool:
            want = want.astype(np.uint8)
        assert back[k].dtype == want.dtype and np.array_equal(back[k], want), k


def test_ply_ascii_fixture_with_faces(tmp_path):
    text = """ply
format ascii 1.0
comment made by hand
element vertex 3
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
property float scalar_intensity
element face 1
property list uchar int vertex_indices
end_header
0.5 1.5 2.5 255 0 10 0.25
1 2 3 0 128 20 0.5
-1 -2 -3 1 2 3 0.75
3 0 1 2
"""
    (tmp_path / "hand.ply").write_text(text)
    cloud = read(tmp_path / "hand.ply")
    assert np.array_equal(cloud.xyz, [[0.5, 1.5, 2.5], [1, 2, 3], [-1, -2, -3]])
    assert cloud.names == ["red", "green", "blue", "scalar_intensity"]
    assert cloud["red"].dtype == np.uint8 and cloud["red"].tolist() == [255, 0, 1]
    assert cloud["scalar_intensity"].dtype == np.float32


def test_ply_big_endian_is_read_in_native_order(tmp_path):
    from plyfile import PlyData, PlyElement

    arr = np.array([(1.0, 2.0, 3.0, 7), (4.0, 5.0, 6.0, 9)], dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("label", ">i4")])
    PlyData([PlyElement.describe(arr, "vertex")], byte_order=">").write(str(tmp_path / "be.ply"))
    cloud = read(tmp_path / "be.ply")
    assert cloud["label"].dtype == np.dtype("=i4") and cloud["label"].tolist() == [7, 9]
    assert cloud.xyz[1].tolist() == [4.0, 5.0, 6.0]


# ------------------------------------------------------------------- ASCII
def test_isprs_pts_with_column_spec(tmp_path):
    (tmp_path / "isprs.pts").write_text(
        "497073.96 5419592.28 265.44 46 2\n497074.27 5419592.31 265.47 31 2\n497075.81 5419593.02 270.10 121 6\n"
    )
    cloud = read(tmp_path / "isprs.pts", columns=["x", "y", "z", "intensity", "classification"])
    assert cloud.xyz[2].tolist() == [497075.81, 5419593.02, 270.10]
    assert cloud["intensity"].dtype == np.uint16 and cloud["intensity"].tolist() == [46, 31, 121]
    assert cloud["classification"].dtype == np.uint8 and cloud["classification"].tolist() == [2, 2, 6]


def test_leica_pts_point_count_line_and_default_columns(tmp_path):
    (tmp_path / "scan.pts").write_text("3\n1.5 2.5 3.5 -120 255 128 0\n2 3 4 -7 1 2 3\n5 6 7 40 9 9 9\n")
    cloud = read(tmp_path / "scan.pts")
    assert cloud.xyz.tolist() == [[1.5, 2.5, 3.5], [2, 3, 4], [5, 6, 7]]  # the count line is not a point
    assert cloud.names == ["intensity", "red", "green", "blue"]
    assert cloud["intensity"].tolist() == [-120, -7, 40]  # PTS intensity is signed: it stays float
    assert cloud["red"].dtype == np.uint16 and cloud["red"].tolist() == [255, 1, 9]
    (tmp_path / "four.pts").write_text("2\n1 2 3 10\n4 5 6 20\n")
    assert read(tmp_path / "four.pts").names == ["intensity"]
    # the same layout as .txt: no default names, and the count line is still skipped
    (tmp_path / "scan.txt").write_text("# from a scanner\n2\n1 2 3 10\n4 5 6 20\n")
    cloud = read(tmp_path / "scan.txt")
    assert cloud.names == ["col3"] and len(cloud) == 2
    (tmp_path / "one.txt").write_text("7\n8\n")  # a one-column file is no cloud
    with pytest.raises(LidarfxError, match="no column named y, z"):
        read(tmp_path / "one.txt")


def test_column_spec_takes_the_header_aliases(tmp_path):
    (tmp_path / "a.txt").write_text("1 2 3 6 200\n4 5 6 2 100\n")
    cloud = read(tmp_path / "a.txt", columns="x,y,z,class,r")
    assert cloud.names == ["classification", "red"]
    assert cloud["classification"].dtype == np.uint8 and cloud["classification"].tolist() == [6, 2]


def test_oakland_xyz_label_conf_defaults(tmp_path):
    (tmp_path / "oakland_part3_am.xyz_label_conf").write_text(
        "-159.57 -51.36 -6.45 1004 1.0\n-159.57 -51.47 -6.46 1100 0.83\n-159.47 -51.48 -6.44 1200 1\n"
    )
    cloud = read(tmp_path / "oakland_part3_am.xyz_label_conf")
    assert cloud.names == ["label", "confidence"]
    assert cloud["label"].dtype == np.int32 and cloud["label"].tolist() == [1004, 1100, 1200]
    assert cloud["confidence"].dtype == np.float64 and cloud["confidence"].tolist() == [1.0, 0.83, 1.0]


def test_cloudcompare_csv_header(tmp_path):
    (tmp_path / "cc.csv").write_text("//X,Y,Z,R,G,B,Intensity\n1.5,2.5,3.5,255,128,0,0.5\n2,3,4,1,2,3,0.25\n")
    cloud = read(tmp_path / "cc.csv")
    assert cloud.names == ["red", "green", "blue", "intensity"]
    assert cloud["red"].dtype == np.uint16 and cloud["red"].tolist() == [255, 1]
    assert cloud["intensity"].dtype == np.float64  # not whole numbers: stays float
    assert cloud.xyz[0].tolist() == [1.5, 2.5, 3.5]


def test_pdal_quoted_header(tmp_path):
    (tmp_path / "pdal.csv").write_text('"X","Y","Z","Classification"\n1.00,2.00,3.00,2\n4.00,5.00,6.00,6\n')
    cloud = read(tmp_path / "pdal.csv")
    assert cloud.names == ["classification"] and cloud["classification"].tolist() == [2, 6]
    assert cloud.xyz.tolist() == [[1, 2, 3], [4, 5, 6]]


def test_text_comments_semicolons_skip_and_defaults(tmp_path):
    (tmp_path / "a.txt").write_text("# exported\n# by hand\n\n1;2;3;9;4\n5;6;7;9;8\n")
    cloud = read(tmp_path / "a.txt")
    assert cloud.names == ["col3", "col4"] and cloud.xyz.tolist() == [[1, 2, 3], [5, 6, 7]]
    cloud = read(tmp_path / "a.txt", columns="x,y,z,-,classification")
    assert cloud.names == ["classification"] and cloud["classification"].tolist() == [4, 8]
    (tmp_path / "b.xyz").write_text("x y z intensity\n1 2 3 10\n4\t5\t6\t20\n")
    cloud = read(tmp_path / "b.xyz")
    assert cloud["intensity"].dtype == np.uint16 and cloud["intensity"].tolist() == [10, 20]


@pytest.mark.parametrize(
    "columns, message",
    [(["x", "y", "intensity"], "no column named z"), (["x", "y", "z", "a", "b", "c"], "6 names"), (["x", "y", "z", "x"], "duplicate")],
)
def test_text_bad_column_spec(tmp_path, columns, message):
    (tmp_path / "a.txt").write_text("1 2 3 4 5\n")
    with pytest.raises(LidarfxError, match=message) as err:
        read(tmp_path / "a.txt", columns=columns)
    assert "a.txt" in str(err.value)


def test_text_messages_quote_the_names_as_written(tmp_path):
    """The aliases (r g b, class) apply to a header, but a message names the columns as the file
    gave them: a header `a b c` is not reported as `a, blue, c`, and a duplicate through an
    alias says which names collided."""
    (tmp_path / "a.txt").write_text("a b c\n1 2 3\n")
    with pytest.raises(LidarfxError, match=r"no column named x, y, z \(columns: a, b, c\)$"):
        read(tmp_path / "a.txt")
    (tmp_path / "b.txt").write_text("x y z red r\n1 2 3 4 5\n")
    with pytest.raises(LidarfxError, match=r"duplicate column name\(s\): red \(r means red\)$"):
        read(tmp_path / "b.txt")
    cloud = read(tmp_path / "b.txt", columns="x,y,z,r,-")  # the alias itself still applies
    assert cloud.names == ["red"]


@pytest.mark.parametrize("ext", [".xyz", ".txt", ".csv", ".pts"])
def test_text_round_trip(tmp_path, ext):
    cloud = small_cloud(300)
    write(cloud, tmp_path / f"t{ext}")
    first = (tmp_path / f"t{ext}").read_text().splitlines()[:2]
    delim = "," if ext == ".csv" else " "
    assert first[0] == delim.join(["x", "y", "z", *cloud.names])
    assert len(first[1].split(delim)[0].split(".")[1]) == 3  # %.3f coordinates
    back = read(tmp_path / f"t{ext}")
    assert np.abs(back.xyz - cloud.xyz).max() <= 0.0005
    assert back["classification"].dtype == np.uint8 and np.array_equal(back["classification"], cloud["classification"])
    assert np.array_equal(back["intensity"], cloud["intensity"])
    assert np.array_equal(back["segment_id"], cloud["segment_id"])
    assert np.allclose(back["planarity"], cloud["planarity"], rtol=1e-14)
    assert np.allclose(back["linearity"], cloud["linearity"], rtol=1e-6)
    assert np.array_equal(back["overhang"], cloud["overhang"].astype(int))


def test_text_precision_option(tmp_path):
    write(PointCloud([[1.23456, 2, 3]]), tmp_path / "p.xyz", precision=1)
    assert (tmp_path / "p.xyz").read_text().splitlines() == ["x y z", "1.2 2.0 3.0"]


# ------------------------------------------------------------------- NumPy
def test_npy_plain_array(tmp_path):
    arr = np.array([[1.0, 2.0, 3.0, 40.0, 2.0], [4.0, 5.0, 6.0, 50.0, 6.0]])
    np.save(tmp_path / "a.npy", arr)
    cloud = read(tmp_path / "a.npy")
    assert cloud.names == ["col3", "col4"] and cloud.xyz.tolist() == [[1, 2, 3], [4, 5, 6]]
    cloud = read(tmp_path / "a.npy", columns=["x", "y", "z", "intensity", "-"])
    assert cloud.names == ["intensity"] and cloud["intensity"].tolist() == [40.0, 50.0]
    write(cloud, tmp_path / "b.npy")
    assert np.array_equal(np.load(tmp_path / "b.npy"), arr[:, :4])


def test_npz_round_trip_is_exact(tmp_path):
    cloud = small_cloud(100)
    cloud["file"] = np.arange(100)  # would clash with numpy.savez's own argument name
    write(cloud, tmp_path / "a.npz", compressed=True)
    back = read(tmp_path / "a.npz")
    assert np.array_equal(back.xyz, cloud.xyz) and back.names == cloud.names
    for k in cloud.names:
        assert back[k].dtype == cloud[k].dtype and np.array_equal(back[k], cloud[k])


# ------------------------------------------------------------------ errors
def test_missing_file(tmp_path):
    with pytest.raises(LidarfxError, match="file not found: .*nothing.laz"):
        read(tmp_path / "nothing.laz")


def test_unknown_extension(tmp_path):
    (tmp_path / "a.e57").write_bytes(b"x")
    with pytest.raises(LidarfxError, match=r"a\.e57: unknown file extension '\.e57'"):
        read(tmp_path / "a.e57")
    with pytest.raises(LidarfxError, match="unknown file extension"):
        write(small_cloud(3), tmp_path / "b.e57")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.e57"]


def test_extension_is_case_insensitive(tmp_path):
    write(small_cloud(20), tmp_path / "UPPER.LAZ")
    assert laspy.open(tmp_path / "UPPER.LAZ").header.are_points_compressed
    assert len(read(tmp_path / "UPPER.LAZ")) == 20


@pytest.mark.parametrize(
    "name, content",
    [
        ("garbage.las", b"this is not a LAS file at all" * 20),
        ("garbage.laz", b"LASF" + bytes(300)),
        ("garbage.ply", b"ply\nformat nonsense 1.0\nend_header\n"),
        ("garbage.npz", b"PK\x03\x04 broken zip"),
        ("garbage.npy", b"\x93NUMPY broken"),
        ("ragged.txt", b"1 2 3 4\n5 6 7\n"),
    ],
)
def test_corrupt_files(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(LidarfxError) as err:
        read(tmp_path / name)
    msg = str(err.value)
    assert name in msg and "\n" not in msg


def test_truncated_laz(tmp_path):
    data = real("samp11-utm.laz").read_bytes()
    (tmp_path / "cut.laz").write_bytes(data[: len(data) // 2])
    with pytest.raises(LidarfxError, match="cut.laz"):
        read(tmp_path / "cut.laz")


def test_output_folder_missing_leaves_nothing(tmp_path):
    with pytest.raises(LidarfxError, match="output folder does not exist"):
        write(small_cloud(5), tmp_path / "no" / "such" / "out.laz")
    assert list(tmp_path.iterdir()) == []


def test_failed_write_leaves_no_partial_file_and_keeps_old_output(tmp_path):
    out = tmp_path / "out.las"
    out.write_bytes(b"previous result")
    bad = PointCloud(np.zeros((4, 3)), {"classification": np.array([1, 2, 3, 999])})
    with pytest.raises(LidarfxError):
        write(bad, out)
    assert out.read_bytes() == b"previous result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.las"]


def test_refuses_to_overwrite_its_input(tmp_path):
    src = tmp_path / "in.laz"
    src.write_bytes(real("samp21-utm.laz").read_bytes())
    before = sha256(src)
    cloud = read(src)
    with pytest.raises(LidarfxError, match="is the input file"):
        write(cloud, src)
    assert sha256(src) == before


def test_unknown_write_option(tmp_path):
    with pytest.raises(LidarfxError, match="ascii not supported for .las"):
        write(small_cloud(3), tmp_path / "a.las", ascii=True)


def test_column_spec_rejected_for_las():
    with pytest.raises(LidarfxError, match="column spec"):
        read(real("samp21-utm.laz"), columns=["x", "y", "z"])


def test_convert_leaves_input_unchanged(tmp_path):
    from lidarfx.cli import main

    src = real("MixedConifer.laz")
    before = sha256(src)
    for ext in (".las", ".laz", ".ply", ".csv", ".npz"):
        assert main(["convert", str(src), str(tmp_path / f"out{ext}")]) == 0
    assert sha256(src) == before
    assert np.array_equal(read(tmp_path / "out.npz")["treeID"], laspy.read(src)["treeID"])


# --------------------------------------------------------------------- size
@pytest.mark.slow
def test_write_one_million_points_with_20_features(tmp_path):
    """A million points with 20 extra-bytes features round-trip exactly (write speeds are measured
    in benchmarks/, e.g. bench_features.py's CLI row with its LAS write)."""
    rng = np.random.default_rng(0)
    n = 1_000_000
    cloud = PointCloud(
        rng.uniform(0, 100, (n, 3)) + [500_000, 5_400_000, 100],
        {f"feature_{i:02d}": rng.random(n).astype(np.float32) for i in range(20)},
    )
    write(cloud, tmp_path / "big.las")
    las = laspy.read(tmp_path / "big.las")
    assert las.header.point_count == n
    assert np.array_equal(np.asarray(las["feature_07"]), cloud["feature_07"])
    assert np.abs(las.x - cloud.xyz[:, 0]).max() <= las.header.scales[0] / 2 + 1e-9


def test_format_for_classes_upgrades_legacy_formats_only():
    import laspy

    from lidarfx.io.las import format_for_classes

    assert format_for_classes(None, 66) is None  # not a LAS cloud
    for legacy, modern in {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}.items():
        h = laspy.LasHeader(point_format=legacy, version="1.2" if legacy < 4 else "1.3")
        assert format_for_classes(h, 31) is None  # 5 bits hold 0..31
        assert format_for_classes(h, 32) == modern
        # the 1.4 format holds every field of the legacy one
        assert set(laspy.PointFormat(legacy).dimension_names) - {"classification_flags", "scan_angle_rank"} <= \
            set(laspy.PointFormat(modern).dimension_names)
    assert format_for_classes(laspy.LasHeader(point_format=6, version="1.4"), 66) is None
