"""``lidarfx eigenclass`` and ``lidarfx eigenclass-references`` from the command line."""
from __future__ import annotations

import json

import numpy as np
import pytest

import lidarfx
from lidarfx import synth
from lidarfx.cli import main
from lidarfx.structures import LABELS, References


@pytest.fixture()
def house(tmp_path):
    path = tmp_path / "house.laz"
    lidarfx.write(synth.house(seed=1, margin=3.0), path)
    return path


def test_eigenclass_writes_labels_and_summary(house, tmp_path, capsys):
    out = tmp_path / "s.laz"
    assert main(["eigenclass", str(house), str(out), "-r", "0.8", "--picture", str(tmp_path / "s.png"),
                 "--keep-signature", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    cloud = lidarfx.read(out)
    lab = np.asarray(cloud["structure"])
    assert lab.dtype == np.int32 and set(np.unique(lab)) <= set(LABELS)
    assert summary["radii"] == [0.8] and sum(summary["counts"].values()) == len(cloud) == summary["points"]
    assert summary["counts"]["plane"] == int((lab == 1).sum()) and summary["counts"]["plane"] > 0.6 * len(cloud)
    for name in ("structure_confidence", "structure_distance", "e1", "e2", "e3", "centroid_offset", "n_neighbours"):
        assert name in cloud
    assert (tmp_path / "s.png").stat().st_size > 1000
    # the same labels as the library call
    ref = lidarfx.classify_structures(lidarfx.read(house), 0.8)
    np.testing.assert_array_equal(ref["structure"], lab)


def test_eigenclass_default_radius_and_multiscale(house, tmp_path, capsys):
    assert main(["eigenclass", str(house), str(tmp_path / "a.laz"), "--json", "-q"]) == 0
    r = json.loads(capsys.readouterr().out)["radii"]
    assert len(r) == 1 and 0.6 < r[0] < 1.1  # about 40 points on the 20 pts/m² roof
    assert main(["eigenclass", str(house), str(tmp_path / "b.laz"), "-r", "0.6", "-r", "0.9", "--keep-signature",
                 "--json", "-q"]) == 0
    cloud = lidarfx.read(tmp_path / "b.laz")
    assert "e1_r0.60" in cloud and "e1_r0.90" in cloud


def test_eigenclass_references_round_trip(tmp_path, house, capsys):
    refs = tmp_path / "refs.json"
    assert main(["eigenclass-references", str(refs), "--counts", "6,24,96", "--samples", "8", "--edge-angles",
                 "90", "--noise", "0,0.01", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    loaded = References.load(refs)
    assert loaded.names == summary["prototypes"] and "edge_90" in loaded.names and len(loaded.names) == 7
    assert list(loaded.counts) == [6, 24, 96] and loaded.parameters["samples"] == 8
    assert main(["eigenclass", str(house), str(tmp_path / "c.laz"), "-r", "0.8", "--references", str(refs), "-q"]) == 0
    assert "structure" in lidarfx.read(tmp_path / "c.laz")


@pytest.mark.parametrize("argv", [
    ["--references", "nofile.json"],
    ["--references", "BAD"],
    ["--reject", "0"],
    ["--reject", "nan"],
    ["--min-neighbours", "2"],
    ["-r", "-1"],
    ["--picture", "x.jpg"],
])
def test_eigenclass_refuses_before_work(house, tmp_path, capsys, argv):
    argv = [a if a != "BAD" else str(tmp_path / "bad.json") for a in argv]
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    out = tmp_path / "o.laz"
    assert main(["eigenclass", str(house), str(out), *argv, "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lidarfx: error:") and "Traceback" not in err
    assert not out.exists()


def test_references_command_refuses(tmp_path, capsys):
    for argv in (["r.txt"], [str(tmp_path / "no" / "r.json")], ["r.json", "--counts", "12,6"],
                 ["r.json", "--noise", "0.9"], ["r.json", "--samples", "1"], ["r.json", "--edge-angles", "200"]):
        assert main(["eigenclass-references", *argv, "-q"]) == 2, argv
        assert capsys.readouterr().err.startswith("lidarfx: error:")


def test_help_has_examples(capsys):
    for cmd in ("eigenclass", "eigenclass-references", "edges"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        text = capsys.readouterr().out
        assert "examples:" in text and f"lidarfx {cmd}" in text
