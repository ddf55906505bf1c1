"""``lidarfx run`` and ``lidarfx.Pipeline``: a pipeline gives the same file as the commands in a
row; malformed and hostile pipeline files are refused with one line and nothing written; the
registry agrees with the commands; docs/pipelines.md lists every step."""
from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx.errors import LidarfxError
from lidarfx.pipeline import STEPS, Pipeline, steps_markdown

ROOT = Path(__file__).resolve().parents[1]
REAL = Path(__file__).resolve().parents[2] / "shared/data/real"
IGN = REAL / "test_data_77055_627755_LA93_IGN69.laz"


# --------------------------------------------------------------------------- helpers
def _terrain(n: int = 4000, seed: int = 0) -> lidarfx.PointCloud:
    """A 40 m x 40 m tilted terrain with a flat-roofed box on it, classes 2 and 6."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 40, (n, 2))
    z = 100 + 0.05 * xy[:, 0] + rng.normal(0, 0.02, n)
    box = (xy[:, 0] > 15) & (xy[:, 0] < 25) & (xy[:, 1] > 15) & (xy[:, 1] < 25)
    z[box] += 6.0
    cls = np.where(box, 6, 2).astype(np.uint8)
    xyz = np.column_stack([xy + [500_000.0, 5_000_000.0], z])
    return lidarfx.PointCloud(xyz, {"classification": cls, "intensity": rng.integers(0, 1000, n).astype(np.uint16)})


def _write_pipeline(path: Path, steps) -> Path:
    path.write_text(json.dumps({"pipeline": steps}))
    return path


def _files(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


# --------------------------------------------------------------------------- acceptance on a real file
@pytest.fixture(scope="module")
def ign_crop(tmp_path_factory):
    if not IGN.is_file():
        pytest.skip(f"real data missing: {IGN} (the shared IGN LiDAR HD test tiles)")
    cloud = lidarfx.read(IGN)
    keep = (cloud.x < cloud.x.min() + 28) & (cloud.y < cloud.y.min() + 28)  # about 22 000 points
    path = tmp_path_factory.mktemp("ign") / "crop.laz"
    lidarfx.write(cloud.subset(keep), path)
    return path


def test_pipeline_equals_the_commands_in_a_row(ign_crop, tmp_path, run_cli):
    """read → ground → features → classify → write gives the same file, byte for byte and field
    by field, as lidarfx ground, lidarfx features and lidarfx classify predict in a row."""
    import laspy

    out = tmp_path / "pipeline.laz"
    pipe = _write_pipeline(tmp_path / "p.json", [
        {"type": "read", "path": str(ign_crop)},
        {"type": "ground", "hag": True},
        {"type": "features", "radius": 1.0, "features": "eigen,plane"},
        {"type": "classify", "model": "default"},
        {"type": "write", "path": str(out)},
    ])
    rc, stdout, err = run_cli(["run", str(pipe), "--json"])
    assert rc == 0, err
    summary = json.loads(stdout)
    assert [s["type"] for s in summary["steps"]] == ["read", "ground", "features", "classify", "write"]
    assert all(s["seconds"] >= 0 for s in summary["steps"])
    assert re.search(r"^\[3/5\] features: 22 features, r = 1 m \(\d+\.\d\d s\)$", err, re.M), err

    g, f, c = tmp_path / "g.laz", tmp_path / "f.laz", tmp_path / "c.laz"
    for argv in (["ground", str(ign_crop), str(g), "--hag"],
                 ["features", str(g), str(f), "-r", "1", "--features", "eigen,plane"],
                 ["classify", "predict", str(f), str(c), "--model", "default"]):
        rc, _, err = run_cli(argv + ["-q"])
        assert rc == 0, err

    a, b = laspy.read(c), laspy.read(out)
    assert list(a.point_format.dimension_names) == list(b.point_format.dimension_names)
    for name in a.point_format.dimension_names:
        assert np.array_equal(np.asarray(a[name]), np.asarray(b[name]), equal_nan=True), name
    assert c.read_bytes() == out.read_bytes()
    # real answers: every point classified into the model's classes, features and heights present
    n = summary["points"]
    assert n == len(b) and 15_000 < n < 30_000
    assert set(np.unique(b.classification)) <= {2, 5, 6} and {2, 6} <= set(np.unique(b.classification))
    assert summary["steps"][1]["ground_points"] == int((np.asarray(laspy.read(g).classification) == 2).sum())
    hag = np.asarray(b["height_above_ground"])
    assert np.nanmax(hag) > 3 and np.isfinite(hag).mean() > 0.99
    assert 0.5 < np.nanmean(np.asarray(b["planarity"])) < 1


# --------------------------------------------------------------------------- Python API
def test_python_api_runs_on_a_cloud_and_reports_each_step():
    cloud = _terrain()
    pipe = Pipeline([{"type": "select", "where": "classification == 6"},
                     {"type": "thin", "cell": 2.0, "keep": "highest"}])
    out = pipe.run(cloud)
    roof = cloud.subset(np.asarray(cloud["classification"]) == 6)
    from lidarfx.thin import thin_cloud

    expected = roof.subset(thin_cloud(roof, 2.0, "highest"))
    assert np.array_equal(out.xyz, expected.xyz)
    assert 20 < len(out) < len(roof)
    assert [s["type"] for s in pipe.summary["steps"]] == ["select", "thin"]
    assert pipe.summary["steps"][0]["kept"] == len(roof)
    assert lidarfx.Pipeline is Pipeline


def test_python_api_needs_a_cloud_or_a_read_step(tmp_path):
    with pytest.raises(LidarfxError, match=r"step 1 is select: a pipeline starts with a read step"):
        Pipeline([{"type": "select", "where": "z > 0"}]).run()
    lidarfx.write(_terrain(), tmp_path / "t.laz")
    with pytest.raises(LidarfxError, match="not both"):
        Pipeline([{"type": "read", "path": str(tmp_path / "t.laz")}]).run(_terrain())
    with pytest.raises(LidarfxError, match="takes a PointCloud"):
        Pipeline([{"type": "select", "where": "z > 0"}]).run(np.zeros((3, 3)))


def test_products_and_writes_in_one_run(tmp_path, run_cli):
    """A dtm product and two writes (the cloud goes on after a write); --input / --output
    replace the read and the last write paths; the outputs are real."""
    src = tmp_path / "terrain.laz"
    lidarfx.write(_terrain(), src)
    pipe = _write_pipeline(tmp_path / "p.json", [
        {"type": "read", "path": "elsewhere.laz"},
        {"type": "write", "path": str(tmp_path / "copy.ply")},
        {"type": "dtm", "output": str(tmp_path / "dtm.asc"), "resolution": 2.0},
        {"type": "select", "where": "classification == 2", "invert": True},
        {"type": "write", "path": "elsewhere_out.laz"},
    ])
    rc, out, err = run_cli(["run", str(pipe), "--input", str(src), "--output", str(tmp_path / "roof.laz"), "--json"])
    assert rc == 0, err
    summary = json.loads(out)
    from lidarfx.ground import dtm

    cloud = lidarfx.read(src)
    expected = dtm(cloud, 2.0, ground=np.asarray(cloud["classification"]) == 2)
    assert summary["steps"][2]["shape"] == list(expected.shape)
    roof = lidarfx.read(tmp_path / "roof.laz")
    assert len(roof) == summary["points"] == summary["steps"][3]["kept"]
    assert set(np.unique(roof["classification"])) == {6}
    assert len(lidarfx.read(tmp_path / "copy.ply")) == 4000
    grid = np.loadtxt(tmp_path / "dtm.asc", skiprows=6)
    assert grid.shape == expected.shape and 99 < grid.min() < grid.max() < 103  # the ground under the box, not its roof
    assert np.allclose(grid, np.asarray(expected.array), atol=1e-3)


def test_crop_reproject_and_dsm_steps_equal_their_functions(tmp_path):
    from lidarfx.crop import crop
    from lidarfx.reproject import reproject
    from lidarfx.surface.models import dsm

    cloud = _terrain()
    box = [500_005.0, 5_000_005.0, 500_035.0, 5_000_035.0]
    pipe = Pipeline([{"type": "crop", "bounds": ",".join(map(str, box)), "buffer": 1},
                     {"type": "dsm", "output": str(tmp_path / "dsm.asc"), "resolution": 2, "max_gap": "inf"},
                     {"type": "reproject", "from": "EPSG:32632", "to": "EPSG:4326"}])
    out = pipe.run(cloud)
    cropped = crop(cloud, bounds=box, buffer=1.0)
    expected = reproject(cropped, "EPSG:4326", source="EPSG:32632")
    assert 2000 < len(out) == len(cropped) < 4000
    assert np.array_equal(out.xyz, expected.xyz) and 8.9 < out.x.min() < out.x.max() < 9.1
    surface = dsm(cropped, 2.0, max_gap=float("inf"))
    grid = np.loadtxt(tmp_path / "dsm.asc", skiprows=6)
    assert grid.shape == surface.shape and np.allclose(grid, surface.array, atol=1e-3)
    assert grid.max() > 106 and grid.min() < 101  # the box's roof and the terrain
    assert [s["type"] for s in pipe.summary["steps"]] == ["crop", "dsm", "reproject"]
    with pytest.raises(LidarfxError, match=r"step 1 \(crop\): no point lies inside the box"):
        Pipeline([{"type": "crop", "bounds": [0, 0, 1, 1]}]).run(cloud)


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path, run_cli):
    src = tmp_path / "t.laz"
    lidarfx.write(_terrain(), src)
    pipe = _write_pipeline(tmp_path / "p.json", [
        str(src), {"type": "ground", "edge-step": 2, "hag": True}, {"type": "thin", "cell": 0.5}, str(tmp_path / "o.laz")])
    before = _files(tmp_path)
    rc, out, err = run_cli(["run", str(pipe), "--dry-run"])
    assert rc == 0, err
    assert "4 steps, valid" in out
    assert re.search(r"^\s+2\s+ground\s+edge_step=2 hag=true$", out, re.M), out
    assert re.search(r"^\s+3\s+thin\s+cell=0.5$", out, re.M), out
    rc, out, _ = run_cli(["run", str(pipe), "--dry-run", "--json"])
    plan = json.loads(out)["steps"]
    assert plan[1]["options"]["edge_step"] == 2.0 and plan[1]["options"]["window"] == 21.0
    assert plan[3] == {"step": 4, "type": "write", "command": "lidarfx convert IN OUT",
                       "options": {**plan[3]["options"], "path": str(tmp_path / "o.laz")},
                       "inputs": [], "outputs": [str(tmp_path / "o.laz")]}
    assert _files(tmp_path) == before


# --------------------------------------------------------------------------- refused pipelines
GOOD_READ = {"type": "read", "path": "IN"}
GOOD_WRITE = {"type": "write", "path": "OUT"}

REFUSED = [
    # (id, steps between read and write or a whole document, the one-line error)
    ("unknown step", [{"type": "grund"}], r"step 2: unknown step type \"grund\"; did you mean 'ground'\?"),
    ("unknown key named", [{"type": "ground", "windw": 20}],
     r"step 2 \(ground\): unknown key \"windw\"; did you mean 'window'\?"),
    ("unknown key listed", [{"type": "thin", "cell": 1, "zzz": 1}],
     r"step 2 \(thin\): unknown key \"zzz\" \(keys: cell, keep, seed\)"),
    ("wrong type", [{"type": "ground", "window": "big"}],
     r"step 2 \(ground\): window must be a finite number, got \"big\""),
    ("bool is not a number", [{"type": "thin", "cell": True}], r"step 2 \(thin\): cell must be a finite number, got true"),
    ("float is not an int", [{"type": "segment", "min_size": 2.5}],
     r"step 2 \(segment\): min_size must be a whole number, got 2.5"),
    ("library range check", [{"type": "ground", "edge_share": 2}],
     r"step 2 \(ground\): edge_share is a share of the boundary from 0 to 1"),
    ("library range check thin", [{"type": "thin", "cell": -1}], r"step 2 \(thin\): cell must be a number in \(0, "),
    ("bad choice", [{"type": "features", "radius": 1, "neighbourhood": "spere"}],
     r"step 2 \(features\): neighbourhood must be one of sphere, cylinder, knn, got \"spere\"; did you mean 'sphere'\?"),
    ("bad feature name", [{"type": "features", "radius": 1, "features": "eigen,planarty"}], r"step 2 \(features\): .*planarty"),
    ("missing required key", [{"type": "select"}], r"step 2 \(select\): missing key 'where'"),
    ("no type", [{"where": "z > 1"}], r"step 2: no \"type\""),
    ("import trick", [{"type": "__import__", "name": "os"}], r"step 2: unknown step type \"__import__\""),
    ("dunder key", [{"type": "thin", "cell": 1, "__class__": "os.system"}], r"step 2 \(thin\): unknown key \"__class__\""),
    ("type not a text", [{"type": ["read"]}], r"step 2: unknown step type \[\"read\"\]"),
    ("expression with a call", [{"type": "select", "where": "__import__('os').system('touch HACKED')"}],
     r"step 2 \(select\): "),
    ("expression with attribute access", [{"type": "select", "where": "z.__class__"}], r"step 2 \(select\): .*attribute"),
    ("nested value", [{"type": "features", "radius": [[[[1.0]]]]}],
     r"step 2 \(features\): radius must be a number or a list of numbers"),
    ("second read", [{"type": "read", "path": "IN"}], r"step 2 \(read\): only the first step reads"),
    ("keys are case-sensitive", [{"type": "thin", "cell": 1, "keep": "first", "KEEP": 1}],
     r"unknown key \"KEEP\"; did you mean 'keep'\?"),
    ("dash and underscore", [{"type": "ground", "edge-step": 1, "edge_step": 2}],
     r"step 2 \(ground\): key 'edge_step' given twice"),
    ("not an object", [42], r"step 2: a step is an object with a \"type\", got 42"),
    ("bad write option", [{"type": "write", "path": "OUTDIR/o.ply", "point_format": 6}],
     r"step 2 \(write\): point_format is not an option of .ply output"),
    ("output is the input", [{"type": "write", "path": "IN"}], r"step 2 \(write\): output .* is an input of step 1"),
    ("output twice", [{"type": "write", "path": "OUT"}], r"step 3 \(write\): output .* is written by step 2 too"),
    ("output folder missing", [{"type": "dtm", "output": "OUTDIR/no/such/dtm.tif"}],
     r"step 2 \(dtm\): output folder does not exist"),
    ("output extension", [{"type": "render", "output": "OUTDIR/p.jpg"}],
     r"step 2 \(render\): output must be a path ending in .png"),
    ("missing model", [{"type": "classify", "model": "OUTDIR/none.skops"}], r"step 2 \(classify\): file not found"),
    ("bad expression", [{"type": "select", "where": "z >"}], r"step 2 \(select\): "),
    ("filter options", [{"type": "filter", "outliers": "radius", "k": 8}], r"step 2 \(filter\): k and std belong to"),
    ("crop area", [{"type": "crop", "bounds": [1, 1, 0, 0]}], r"step 2 \(crop\): .*minimum exceeds its maximum"),
    ("missing polygon", [{"type": "crop", "polygon": "OUTDIR/area.geojson"}],
     r"step 2 \(crop\): file not found: .*area.geojson"),
    ("unknown CRS", [{"type": "reproject", "to": "EPSG:99999999"}], r"step 2 \(reproject\): to: unknown CRS"),
]


@pytest.mark.parametrize("steps, message", [r[1:] for r in REFUSED], ids=[r[0] for r in REFUSED])
def test_refused_with_one_line_and_nothing_written(tmp_path, run_cli, steps, message):
    src = tmp_path / "in.laz"
    lidarfx.write(_terrain(400), src)
    out = tmp_path / "out.laz"

    def fill(v):
        if isinstance(v, dict):
            return {k: fill(x) for k, x in v.items()}
        if isinstance(v, list):
            return [fill(x) for x in v]
        if isinstance(v, str):
            return {"IN": str(src), "OUT": str(out)}.get(v, v.replace("OUTDIR", str(tmp_path)))
        return v

    pipe = _write_pipeline(tmp_path / "p.json", fill([GOOD_READ, *steps, GOOD_WRITE]))
    before = _files(tmp_path)
    rc, stdout, err = run_cli(["run", str(pipe)])
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith(f"lidarfx: error: {pipe}: "), err
    assert re.search(message, err), err
    assert _files(tmp_path) == before and not (tmp_path / "HACKED").exists()
    assert stdout == ""


DOCUMENTS = [
    ("not JSON", "pipeline:\n  - read: in.laz\n", r"not JSON: Expecting value at line 1 column 1"),
    ("truncated", '{"pipeline": [{"type": "read", "path": "in.laz"}', r"not JSON: .* at line 1"),
    ("huge nesting", "[" * 100_000 + "]" * 100_000, r"nested too deeply"),
    ("deep nesting", json.dumps({"pipeline": [{"type": "read", "path": [[[[[[[[["x"]]]]]]]]]}]}), r"nested too deeply"),
    ("NaN", '{"pipeline": [{"type": "read", "path": "in.laz"}, {"type": "thin", "cell": NaN}]}',
     r"NaN is not a JSON number"),
    ("infinite", '[{"type": "read", "path": "in.laz"}, {"type": "thin", "cell": 1e999}]',
     r"step 2 \(thin\): cell must be a finite number"),
    ("huge integer", '[{"type": "read", "path": "in.laz"}, {"type": "thin", "cell": ' + "9" * 5000 + "}]",
     r"not a pipeline: a number with too many digits"),
    ("empty", "[]", r"the pipeline has no steps"),
    ("not a list", '"in.laz"', r"a pipeline is a list of steps"),
    ("top-level key", '{"pipeline": [], "steps": []}', r"unknown key \"steps\" at the top"),
    ("duplicate top key", '{"pipeline": [], "pipeline": []}', r"key 'pipeline' given twice"),
    ("duplicate step key", '[{"type": "read", "path": "a.laz", "path": "b.laz"}]',
     r"step 1 \(read\): key 'path' given twice"),
    ("no read", '[{"type": "thin", "cell": 1}, {"type": "write", "path": "o.laz"}]',
     r"step 1 is thin: a pipeline starts with a read step"),
    ("writes nothing", '["IN"]', r"the pipeline writes nothing"),
    ("file name in the middle", '["in.laz", "mid.laz", "out.laz"]', r"step 2: a file name stands for the read step"),
    ("binary", b"\xff\xfe\x00\x01garbage", r"not UTF-8 text"),
    ("too big", "[" + " " * (1 << 20) + "]", r"bytes is not a pipeline"),
    ("missing input", '["missing.laz", "out.laz"]', r"step 1 \(read\): file not found: missing.laz"),
]


@pytest.mark.parametrize("text, message", [d[1:] for d in DOCUMENTS], ids=[d[0] for d in DOCUMENTS])
def test_malformed_documents_refused(tmp_path, run_cli, monkeypatch, text, message):
    monkeypatch.chdir(tmp_path)
    lidarfx.write(_terrain(100), tmp_path / "in.laz")
    pipe = tmp_path / "p.json"
    if isinstance(text, bytes):
        pipe.write_bytes(text)
    else:
        pipe.write_text(text.replace('"IN"', '"in.laz"'))
    before = _files(tmp_path)
    rc, stdout, err = run_cli(["run", "p.json"])
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and len(err) < 400, err
    assert re.search(message, err), err
    assert _files(tmp_path) == before and stdout == ""


def test_yaml_and_missing_files_refused(tmp_path, run_cli):
    (tmp_path / "p.yaml").write_text("pipeline: []\n")
    rc, _, err = run_cli(["run", str(tmp_path / "p.yaml")])
    assert rc == 2 and "pipelines are JSON files (YAML is not read)" in err
    rc, _, err = run_cli(["run", str(tmp_path / "none.json")])
    assert rc == 2 and "pipeline file not found" in err


def test_existing_output_needs_force(tmp_path, run_cli):
    src, out = tmp_path / "in.laz", tmp_path / "out.laz"
    lidarfx.write(_terrain(300), src)
    out.write_bytes(b"old")
    pipe = _write_pipeline(tmp_path / "p.json", [str(src), {"type": "thin", "cell": 5.0}, str(out)])
    rc, _, err = run_cli(["run", str(pipe), "-q"])
    assert rc == 2 and f"step 3 (write): {out} exists; give --force" in err
    assert out.read_bytes() == b"old"
    rc, _, err = run_cli(["run", str(pipe), "-q", "--force"])
    assert rc == 0, err
    assert 0 < len(lidarfx.read(out)) < 300


def test_python_api_refuses_early():
    with pytest.raises(LidarfxError, match=r"^pipeline: step 1 \(features\): give a radius"):
        Pipeline([{"type": "features"}])
    with pytest.raises(LidarfxError, match=r"^pipeline: step 1 \(colour\): sun altitude must be 0 to 90 degrees"):
        Pipeline([{"type": "colour", "sun_altitude": 120}])
    with pytest.raises(LidarfxError, match=r"step 1 \(edges\): output must be a path ending in .geojson or .json"):
        Pipeline([{"type": "edges", "output": "lines.shp"}])
    with pytest.raises(LidarfxError, match=r"step 1 \(powerlines\): .*load case"):
        Pipeline([{"type": "powerlines", "outdir": "out", "load_case": ["temp=hot"]}])
    p = Pipeline([{"type": "structures", "radius": [0.5, 1]}, {"type": "color", "by": "structure"}])
    assert [s.name for s, _ in p.steps] == ["eigenclass", "colour"]


# --------------------------------------------------------------------------- registry and docs
def _command_parser(command: str) -> argparse.ArgumentParser:
    from lidarfx.cli import build_parser

    p = build_parser()
    for word in command.split()[1:]:
        if word.startswith("-") or not word.replace("-", "").isalpha():
            break
        p = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)][0].choices[word]
    return p


@pytest.mark.parametrize("name", [n for n in STEPS if n not in ("read", "write")])
def test_keys_are_the_commands_options_with_their_defaults(name):
    """Every key of a step is a long option (or the output argument) of its command, with the
    command's default and choices."""
    step = STEPS[name]
    parser = _command_parser(step.command)
    options = {}
    for a in parser._actions:
        for o in a.option_strings:
            if o.startswith("--"):
                options[o[2:].replace("-", "_")] = a
        if not a.option_strings:
            options[a.dest] = a
    options.setdefault("k", next((a for a in parser._actions if "-k" in a.option_strings), None))
    for key in step.keys:
        action = options.get(key.name)
        assert action is not None, f"{name}: {key.name} is no option of {step.command}"
        if key.kind != "csv":  # the command's --csv [PATH]: absent = None, as the key's default
            assert action.default == key.default, (name, key.name, action.default, key.default)
        if action.choices and key.kind == "choice":
            assert tuple(action.choices) == key.choices, (name, key.name)


def test_docs_list_every_step_from_the_registry():
    text = (ROOT / "docs" / "pipelines.md").read_text(encoding="utf-8")
    begin, end = "<!-- steps: generated by `lidarfx run --steps --markdown` -->", "<!-- steps: end -->"
    assert begin in text and end in text
    section = text.split(begin, 1)[1].split(end, 1)[0]
    assert section.strip() == steps_markdown().strip(), "run `lidarfx run --steps --markdown` and paste it"
    for name in STEPS:
        assert f"\n### {name}\n" in section
    assert "docs/pipelines.md" in (ROOT / "README.md").read_text(encoding="utf-8")
