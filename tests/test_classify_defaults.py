"""Defaults of ``classify train`` fitted to the training data (issue 31 item 3): the return inputs
left out of clouds without return numbers, radii from the measured point spacing; and the model
shipped with lidarfx (``--model default``)."""
from __future__ import annotations

import json
import math
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.classify import TrainConfig, load_model, train
from lidarfx.classify.model import DEFAULT_MODEL, model_path, read_sources, resolve_defaults
from lidarfx.classify.pipeline import point_spacing, return_information, spacing_radii
from lidarfx.cli import main
from lidarfx.errors import LidarfxError, LidarfxWarning

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real"
FACADE6 = "ground=2,vegetation=5,wall=6,roof=64,window=65,clutter=66"
#: everything but the features and the radii kept small: these tests are about the defaults
FAST = dict(max_per_class=300, n_estimators=10, terrain_augment=0)
CLI_FAST = ["--max-per-class", "300", "--n-estimators", "10", "--terrain-augment", "0"]


@pytest.fixture(scope="module")
def scan():
    """A TLS facade without return numbers (the fields are absent)."""
    c = lidarfx.synth.facade(seed=1, density=60.0)
    assert "return_number" not in c
    return c


def _with_returns(cloud, rn, nr):
    n = len(cloud)
    return lidarfx.PointCloud(cloud.xyz, {**cloud.attrs, "return_number": np.broadcast_to(rn, n).astype(np.uint8),
                                          "number_of_returns": np.broadcast_to(nr, n).astype(np.uint8)})


# --------------------------------------------------------------------------- 1. no return numbers
def test_default_features_fall_back_without_return_numbers(scan):
    """Before: 'the features include return_ratio but the cloud has no return_number field'."""
    with pytest.warns(LidarfxWarning, match="no return numbers .* leave out return_ratio, number_of_returns"):
        model = train(scan, classes=FACADE6, **FAST)
    names = model.feature_names
    assert "return_ratio" not in names and "number_of_returns" not in names and "height_above_ground" in names
    assert model.meta["config"]["features"] == ["default", "-return_ratio", "-number_of_returns"]
    assert model.meta["training"]["defaults"]["returns"]["files"] == {"cloud 1": "none"}
    assert model.min_building_area == 10.0  # still the ALS default list, with its building rule
    codes = model.predict(scan)
    assert (codes >= 0).all()
    # with a log the notice is one line there, and no warning
    lines = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        train(scan, classes=FACADE6, log=lines.append, **FAST)
    notes = [s for s in lines if s.startswith("note: no return numbers")]
    assert len(notes) == 1 and "\n" not in notes[0]


def test_zero_and_single_returns_fall_back_multi_returns_do_not(scan):
    zero, single = _with_returns(scan, 0, 0), _with_returns(scan, 1, 1)
    assert return_information(zero) == "none" and return_information(single) == "single"
    rn = np.where(np.arange(len(scan)) % 3 == 0, 2, 1)
    multi = _with_returns(scan, rn, 2)
    assert return_information(multi) == "multi"
    cfg = TrainConfig()
    for clouds, dropped, what in (([zero], True, "no return numbers"), ([single], True, "only single returns"),
                                  ([single, multi], False, None), ([multi], False, None),
                                  ([zero, multi], True, "no return numbers")):
        got, notes = resolve_defaults(cfg, read_sources(clouds), log=lambda m: None)
        assert ("return_ratio" not in got.feature_names()) == dropped, (what, len(clouds))
        if dropped:
            assert what in notes["returns"]["note"]
        else:
            assert got.features is None and notes["returns"] is None
    # a list given explicitly is never changed: the missing field is refused, with the hint
    with pytest.raises(LidarfxError, match="no return information"):
        train(zero, classes=FACADE6, features="eigen,number_of_returns", radii=[0.5], **FAST)


def test_cli_train_scan_model_with_the_defaults(scan, tmp_path, capsys):
    """``lidarfx classify train scan.laz model.skops``: the model as the last file, defaults fitted."""
    path, model = tmp_path / "scan.laz", tmp_path / "model.skops"
    lidarfx.write(scan, path)  # LAS: the return fields exist and hold 0
    assert main(["classify", "train", str(path), str(model), "--classes", FACADE6, *CLI_FAST, "--json"]) == 0
    cap = capsys.readouterr()
    summary = json.loads(cap.out)
    assert summary["model"] == str(model) and model.is_file()
    assert [line for line in cap.err.splitlines() if line.startswith("note: no return numbers")] == [
        f"note: no return numbers (fields missing or 0 in every point) in {path}: the default features leave out "
        "return_ratio, number_of_returns (--features default,-return_ratio,-number_of_returns)"]
    assert main(["classify", "predict", str(path), str(tmp_path / "out.laz"), "--model", str(model), "-q"]) == 0
    # without a model: one line naming both ways
    assert main(["classify", "train", str(path), "-q"]) == 2
    assert "give the output model: --model M.skops, or M.skops as the last file" in capsys.readouterr().err


# --------------------------------------------------------------------------- 2. radii from the spacing
def test_point_spacing_of_a_uniform_plane():
    rng = np.random.default_rng(3)
    for density in (25.0, 400.0):
        n = int(density * 400)
        xyz = np.column_stack([rng.uniform(0, 20, n), rng.uniform(0, 20, n), np.zeros(n)])
        assert point_spacing(xyz) == pytest.approx(1 / math.sqrt(density), rel=0.05)


def test_spacing_radii_rule():
    assert spacing_radii(0.2) == [1.0, 2.0, 3.0]  # ALS (25 pts/m²)
    assert spacing_radii(0.16) == [1.0, 2.0, 3.0]  # a 1 m disc holds 123 points: still ALS
    assert spacing_radii(0.05) == [0.32, 0.64, 0.96]  # 400 pts/m²: r = √(125/π) · 0.05
    assert spacing_radii(1e-4) == [0.01, 0.02, 0.03]  # at least 1 cm
    assert spacing_radii(3.0) == [1.0, 2.0, 3.0]  # never larger than the ALS radii


@pytest.fixture(scope="module")
def sparse_dense():
    """An MLS street at 25 and at 600 points/m² (within 5 m of the driving line)."""
    return (lidarfx.synth.street(seed=2, length=30.0, density=25.0),
            lidarfx.synth.street(seed=2, length=30.0, density=600.0))


def test_default_radii_come_from_the_point_spacing(sparse_dense, tmp_path):
    """Before: 1, 2, 3 m whatever the density."""
    sparse, dense = sparse_dense
    classes = "ground=2,vegetation=5,building=6,wire=14,pole=64,car=65"
    models = {}
    for name, cloud in (("sparse", sparse), ("dense", dense)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LidarfxWarning)  # (no return numbers)
            models[name] = train(cloud, classes=classes, **FAST)
    s_sparse, s_dense = point_spacing(sparse.xyz), point_spacing(dense.xyz)
    assert s_sparse > 0.16 > s_dense
    assert models["sparse"].radii == [1.0, 2.0, 3.0]
    r = round(math.sqrt(125 / math.pi) * s_dense, 2)
    assert models["dense"].radii == [r, round(2 * r, 2), round(3 * r, 2)] and 0.2 < r < 0.6
    # recorded in the model: the radii, that they came from the spacing, the spacing itself
    m = models["dense"]
    assert m.meta["config"]["auto_radii"] is True
    sp = m.meta["training"]["defaults"]["spacing"]
    assert sp["spacing"] == pytest.approx(s_dense, abs=1e-4) and sp["radii"] == m.radii
    assert any(n.endswith(f"_r{r:.2f}") for n in m.feature_names)
    loaded = load_model(m.save(tmp_path / "dense.skops"))
    assert loaded.radii == m.radii and loaded.summary()["defaults"]["spacing"]["radii"] == m.radii
    np.testing.assert_array_equal(loaded.predict(dense), m.predict(dense))
    # given radii stay as given
    given = train(dense, classes=classes, features="eigen", radii=[1.0, 2.0], **FAST)
    assert given.radii == [1.0, 2.0] and given.meta["config"]["auto_radii"] is False


def test_cli_help_and_evaluate_use_the_spacing_radii(sparse_dense, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["classify", "train", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "from the measured point spacing" in out and "recorded in the model" in out
    assert "leaves out return_ratio and number_of_returns" in out
    _, dense = sparse_dense
    path = tmp_path / "dense.laz"
    lidarfx.write(dense, path)
    assert main(["classify", "evaluate", str(path), "--classes", "2,5,6,14,64", "--cv", "2", "--no-random-folds",
                 "--spatial-blocks", "10", "--bootstrap", "0", "--features", "eigen", *CLI_FAST, "--json", "-q"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["config"]["radii"] == spacing_radii(point_spacing(lidarfx.read(path).xyz))
    assert rep["config"]["radii"][0] < 1.0


# --------------------------------------------------------------------------- 3. the shipped model
needs_default = pytest.mark.skipif(not DEFAULT_MODEL.is_file(), reason=f"default model not built: {DEFAULT_MODEL}")
SMALL_REAL = REAL / "file_with_both_wkt_and_geotiff_vlrs.las"  # 25 408 points, another survey (US feet)


@needs_default
def test_the_default_model_ships_small_and_packaged():
    assert DEFAULT_MODEL.stat().st_size < 4_000_000  # a few MB
    assert model_path("default") == DEFAULT_MODEL
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LidarfxWarning)  # another scikit-learn than the build's
        m = load_model("default")
    assert list(m.classes.names) == ["ground", "vegetation", "building"]
    assert [list(g) for g in m.classes.groups] == [[2], [3, 4, 5], [6]]
    assert m.radii == [1.0, 2.0, 3.0] and len(m.feature_names) == 81
    assert [f["name"] for f in m.meta["training"]["files"]] == [
        f"test_data_{t}_627755_LA93_IGN69.laz" for t in ("77050", "77055", "77060")]
    assert m.meta["card"] == "docs/default-model.md" and "Etalab 2.0" in m.meta["licence"]
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["lidarfx"]
    assert "data/models/*.skops" in data
    # the card names what the model holds
    card = (ROOT / "docs" / "default-model.md").read_text(encoding="utf-8")
    for name, codes in (("ground", "2"), ("vegetation", "3+4+5"), ("building", "6")):
        assert f"| {name} | {codes} |" in card
    assert "81" in card and "1, 2 and 3 m" in card and "Licence Ouverte / Etalab 2.0" in card
    assert "python benchmarks/build_default_model.py" in card


@needs_default
def test_classify_info_default_prints_the_cards_classes(capsys):
    assert main(["classify", "info", "default"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    for text in ("ground codes 2", "vegetation codes 3+4+5", "building codes 6", "81 columns; radii 1, 2, 3 m"):
        assert text in out
    assert main(["classify", "info", "default", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [c["name"] for c in info["classes"]] == ["ground", "vegetation", "building"]
    assert info["card"] == "docs/default-model.md"


@needs_default
@pytest.mark.skipif(not SMALL_REAL.is_file(), reason=f"small real file not found: {SMALL_REAL}")
def test_model_default_predicts_a_small_real_file(tmp_path, capsys):
    out = tmp_path / "out.laz"
    assert main(["classify", "predict", str(SMALL_REAL), str(out), "--model", "default", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["model"] == "default" and summary["predicted"] == summary["points"]
    ref = np.asarray(lidarfx.read(SMALL_REAL)["classification"])
    pred = np.asarray(lidarfx.read(out)["classification"])
    assert set(np.unique(pred)) <= {2, 5, 6}
    lab = np.isin(ref, [2, 3, 4, 5, 6])
    merged = np.where(np.isin(ref, [3, 4, 5]), 5, ref)
    assert (pred[lab] == merged[lab]).mean() > 0.85  # docs/default-model.md: OA 0.90 on this file
    # evaluate --model default, the same file
    assert main(["classify", "evaluate", str(SMALL_REAL), "--model", "default", "--bootstrap", "0", "--json",
                 "-q"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["model"] == "default" and rep["sections"]["test"]["metrics"]["oa"] > 0.85


def test_a_missing_default_model_is_one_line(monkeypatch, capsys, tmp_path):
    import lidarfx.classify.model as M

    monkeypatch.setattr(M, "DEFAULT_MODEL", tmp_path / "none.skops")
    with pytest.raises(LidarfxError, match="the default model is not installed .*build_default_model.py"):
        load_model("default")
    assert main(["classify", "info", "default"]) == 2
    assert "default model is not installed" in capsys.readouterr().err
