"""Nothing runs from data (docs/reliability.md, "Nothing runs from data").

Crafted model files, selection expressions and config-like files (structure references, the
chunked engine's work folder, polygons, line approximations, tower truth, pipelines, load cases,
scene parameters) are refused with one line (CLI) or a LidarfxError (API).  Each code payload
would create a marker file if it ran; the tests show that it does (a positive control, loading
the payload the unsafe way) and that lidarfx never lets it.
"""
from __future__ import annotations

import copy
import functools
import io
import json
import os
import pickle
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

import lidarfx
from lidarfx import LidarfxError
from lidarfx.classify.model import DEFAULT_MODEL, TRUSTED_TYPES, load_model, untrusted_types
from lidarfx.select import evaluate

SRC = Path(lidarfx.__file__).parent


def one_line(rc: int, err: str) -> str:
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("lidarfx: error: ") and "Traceback" not in err, (rc, err)
    return lines[0]


@pytest.fixture(scope="module")
def cloud_file(tmp_path_factory) -> Path:
    from test_reliability_degenerate import _write_las, scene

    d = tmp_path_factory.mktemp("nocode")
    xyz, cls = scene()
    _write_las(d / "scene.las", xyz, cls)
    return d / "scene.las"


# ------------------------------------------------------------------------------ payloads
class _Payload:
    """Unpickling it runs ``touch MARKER``."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch '{self.marker}'",)


def _json_str(text: str, ident: int) -> dict:
    return {"__class__": "str", "__module__": "builtins", "__loader__": "JsonNode", "content": json.dumps(text),
            "is_json": True, "__id__": ident}


def _node_system(marker: Path) -> dict:
    """``os.system("touch MARKER")`` as a skops node (built by calling the 'constructor')."""
    return {"__class__": "system", "__module__": os.system.__module__, "__loader__": "ConstructorFromReduceNode",
            "content": {"__class__": "tuple", "__module__": "builtins", "__loader__": "TupleNode",
                        "content": [_json_str(f"touch '{marker}'", 901)], "__id__": 902}, "__id__": 903}


def _node_partial(marker: Path) -> dict:
    """A reference to ``functools.partial(os.system, "touch MARKER")``, as skops writes it."""
    import skops.io as sio

    data = sio.dumps({"p": functools.partial(os.system, f"touch '{marker}'")})
    return json.loads(zipfile.ZipFile(io.BytesIO(data)).read("schema.json"))["content"]["p"]


def _empty_dict_node() -> dict:
    import skops.io as sio

    return json.loads(zipfile.ZipFile(io.BytesIO(sio.dumps({}))).read("schema.json"))


NODES = {
    "eval": lambda m: {"__class__": "eval", "__module__": "builtins", "__loader__": "TypeNode", "__id__": 904},
    "os.system": _node_system,
    "partial": _node_partial,
    "import": lambda m: {"__class__": "Evil", "__module__": "lidarfx_evil_module", "__loader__": "ObjectNode",
                         "content": _empty_dict_node(), "__id__": 906},
}
"""Hostile skops nodes put in place of the model's ``format`` entry."""


def _rewrite(src: Path, dst: Path, schema: dict | str | None = None, extra: dict | None = None) -> Path:
    """``src`` (a skops zip) with another schema (a dict, or the text of schema.json) and extra members."""
    text = json.dumps(schema) if isinstance(schema, dict) else schema
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = text.encode() if text is not None and info.filename == "schema.json" else zin.read(info)
            zout.writestr(info.filename, data)
        for name, data in (extra or {}).items():
            zout.writestr(name, data)
    return dst


def _schema() -> dict:
    with zipfile.ZipFile(DEFAULT_MODEL) as z:
        return json.loads(z.read("schema.json"))


def _evil_module(folder: Path, marker: Path) -> None:
    (folder / "lidarfx_evil_module.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).touch()\n\nclass Evil(dict):\n"
        f"    def __setstate__(self, state):\n        Path({str(marker)!r}).touch()\n")


@pytest.fixture
def crafted(tmp_path, monkeypatch):
    """``crafted(kind)`` → (model file, marker): the shipped model with a hostile node or member."""
    marker = tmp_path / "MARKER"
    _evil_module(tmp_path, marker)
    monkeypatch.syspath_prepend(str(tmp_path))  # the hostile module is importable: it must not be imported

    def make(kind: str) -> tuple[Path, Path]:
        schema = _schema()
        if kind in NODES:
            schema["content"]["format"] = NODES[kind](marker)
            return _rewrite(DEFAULT_MODEL, tmp_path / f"{kind}.skops", schema), marker
        if kind == "object-array":  # a numpy array member whose objects unpickle to os.system(...)
            buf = io.BytesIO()
            np.save(buf, np.array([_Payload(marker)], dtype=object), allow_pickle=True)
            schema["content"]["format"] = {"__class__": "ndarray", "__module__": "numpy", "__loader__": "NdArrayNode",
                                           "type": "numpy", "file": "evil.npy", "__id__": 907}
            return _rewrite(DEFAULT_MODEL, tmp_path / "array.skops", schema, {"evil.npy": buf.getvalue()}), marker
        raise KeyError(kind)

    return make


@pytest.mark.parametrize("kind", list(NODES))
def test_a_model_naming_an_untrusted_type_is_refused_before_anything_is_built(crafted, kind):
    path, marker = crafted(kind)
    bad = untrusted_types(path)
    assert bad and not set(bad) & set(TRUSTED_TYPES)
    with pytest.raises(LidarfxError, match="refusing to load: the file contains types a lidarfx model never holds"):
        load_model(path)
    assert not marker.exists()


def test_the_payloads_are_real(crafted):
    """Positive control: loaded the unsafe way (every type trusted), the payloads do run."""
    import skops.io as sio

    for kind in ("os.system", "import", "object-array"):
        path, marker = crafted(kind)
        marker.unlink(missing_ok=True)
        try:
            if kind == "object-array":
                with zipfile.ZipFile(path) as z:
                    np.load(io.BytesIO(z.read("evil.npy")), allow_pickle=True)
            else:
                sio.load(path, trusted=sio.get_untrusted_types(file=path))
        except Exception:
            pass  # the model around the payload is broken now; the payload ran first
        assert marker.exists(), kind


def test_a_pickled_object_array_inside_a_model_is_not_unpickled(crafted):
    path, marker = crafted("object-array")
    assert untrusted_types(path) == []  # only trusted type names: the array itself is the payload
    with pytest.raises(LidarfxError, match="cannot load the model"):
        load_model(path)
    assert not marker.exists()


def test_not_a_model_pickle_garbage_and_a_zip_bomb(tmp_path):
    marker = tmp_path / "MARKER"
    pickled = tmp_path / "pickled.skops"
    pickled.write_bytes(pickle.dumps(_Payload(marker)))
    garbage = tmp_path / "garbage.skops"
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    truncated = tmp_path / "truncated.skops"
    truncated.write_bytes(DEFAULT_MODEL.read_bytes()[:100_000])
    noschema = tmp_path / "noschema.skops"
    with zipfile.ZipFile(noschema, "w") as z:
        z.writestr("model.bin", b"\0" * 100)
    bomb = tmp_path / "bomb.skops"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z, z.open("schema.json", "w", force_zip64=True) as fh:
        for _ in range(64):
            fh.write(b" " * 2**20)  # 64 MiB of blanks in about 64 kB
    assert bomb.stat().st_size < 2**20
    deep = _rewrite(DEFAULT_MODEL, tmp_path / "deep.skops", "[" * 100_000 + "]" * 100_000)
    for path, why in [(pickled, "not a skops model file"), (garbage, "not a skops model file"),
                      (truncated, "not a skops model file"), (noschema, "not a skops model file"),
                      (bomb, "refusing to load: it would unpack to"), (deep, "not a skops model file")]:
        with pytest.raises(LidarfxError, match=why) as exc:
            load_model(path)
        assert "\n" not in str(exc.value)
    assert not marker.exists()
    pickle.loads(pickled.read_bytes())  # positive control: unpickling runs the payload
    assert marker.exists()


@pytest.mark.parametrize("kind", ["os.system", "import", "object-array"])
def test_classify_predict_refuses_a_crafted_model_in_one_line(crafted, cloud_file, tmp_path, run_cli, kind):
    path, marker = crafted(kind)
    out = tmp_path / "out.laz"
    rc, _, err = run_cli(["classify", "predict", str(cloud_file), str(out), "--model", str(path), "-q"])
    line = one_line(rc, err)
    assert "refusing to load" in line or "cannot load the model" in line
    assert not out.exists() and not marker.exists()
    rc, _, err = run_cli(["classify", "info", str(path)])
    one_line(rc, err)
    assert not marker.exists()


def test_the_shipped_model_still_loads():
    assert untrusted_types(DEFAULT_MODEL) == []
    model = load_model("default")
    assert len(model.classes) == 3


# --------------------------------------------------------------------------- expressions
HOSTILE_EXPRESSIONS = [
    "__import__('os').system('touch MARKER')",
    "__import__",
    "x.__class__",
    "x.real > 0",
    "(lambda: 1)() > 0",
    "[i for i in [1]] == 1",
    "{i: 1 for i in [1]}",
    "__builtins__ > 0",
    "abs(x) > 0",
    "x[0] > 0",
    "'touch MARKER'",
    "f'{x}' > 0",
    "(y := 1) > 0",
    "x > 0; __import__('os')",
    "x if x > 0 else y",
    "(" * 5000 + "x" + ")" * 5000 + " > 0",
    "not " * 2400 + "x > 0",
    "-" * 9000 + "x > 0",
    "x" + " ** x" * 2000 + " > 0",
    "x" + " + x" * 3000 + " > 0",
    "x in [" + "(" * 3000 + "1" + ")" * 3000 + "]",
    "x > " + "9" * 20_000,
]


@pytest.mark.parametrize("expr", HOSTILE_EXPRESSIONS, ids=lambda e: re.sub(r"\W+", "_", e[:24]))
def test_hostile_selection_expressions_are_refused(cloud_file, tmp_path, run_cli, monkeypatch, expr):
    monkeypatch.chdir(tmp_path)
    cloud = lidarfx.read(cloud_file)
    with pytest.raises(LidarfxError) as exc:
        evaluate(cloud, expr)
    assert "\n" not in str(exc.value)
    out = tmp_path / "out.laz"
    rc, _, err = run_cli(["select", str(cloud_file), str(out), "-w", expr, "-q"])
    one_line(rc, err)
    assert not out.exists() and not (tmp_path / "MARKER").exists()


def test_deep_but_reasonable_expressions_still_work(cloud_file):
    cloud = lidarfx.read(cloud_file)
    n = len(cloud)
    assert evaluate(cloud, "(" * 40 + "z > 1" + ")" * 40).sum() == (cloud.xyz[:, 2] > 1).sum()
    assert evaluate(cloud, "z" + " + 0" * 150 + " > 1").sum() == (cloud.xyz[:, 2] > 1).sum()
    assert evaluate(cloud, "not " * 40 + "z > 1").sum() == (cloud.xyz[:, 2] > 1).sum()
    assert evaluate(cloud, "classification in [2, 9] or z > 1e300").sum() == (cloud["classification"] == 2).sum() < n


# ---------------------------------------------------------------------------- the source
def test_the_source_has_no_eval_exec_pickle_or_yaml_loading():
    """Data is parsed by json / numpy (allow_pickle=False) / laspy / skops with trusted types only;
    the one pickle read is numba's cache index of the shipped kernels (package data, never a
    user's file), and modules are imported by name only from lidarfx's own fixed lists."""
    hits = {}
    pattern = re.compile(r"(?<![\w.])(eval|exec|compile|__import__)\(|pickle\.loads?\(|yaml\.(unsafe_)?load\(|"
                         r"allow_pickle=True|marshal\.|shelve\.|import_module\(")
    for path in sorted(SRC.rglob("*.py")):
        for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("#")[0]
            if pattern.search(code) and not code.strip().startswith(("\"", "'")):
                hits[f"{path.relative_to(SRC)}:{lineno}"] = code.strip()
    allowed = {"_prebuilt.py": "pickle.load(f)", "__init__.py": "import_module(f\".{name}\"",
               "cli/__init__.py": "import_module(f\"{__name__}.{name}\")", "io/__init__.py": "import_module(f\"{__name__}.{name}\")",
               "tiles/processors.py": "import_module(f\"{__package__}.{_MODULES[command]}\")"}
    for where, code in hits.items():
        assert any(where.startswith(f + ":") and snippet in code for f, snippet in allowed.items()), (where, code)
    assert len(hits) >= 4


# ------------------------------------------------------------------------- config files
HOSTILE_JSON = {
    "import": '{"__import__": "os", "system": "touch MARKER", "format": "__import__(\'os\')"}',
    "list": "[1, 2, 3]",
    "nan": '{"a": NaN, "format": Infinity}',
    "huge": '{"a": 1e999}',
    "bigint": '{"a": ' + "9" * 5000 + "}",
    "deep": "[" * 100_000 + "]" * 100_000,
    "binary": "\x00\x01\x02binary",
    "empty": "",
}


def _hostile_file(folder: Path, kind: str, suffix: str) -> Path:
    p = folder / f"hostile_{kind}{suffix}"
    p.write_text(HOSTILE_JSON[kind], encoding="utf-8")
    return p


CONFIG_COMMANDS = {
    "references": lambda f, h, o: ["eigenclass", f, o / "o.laz", "-r", "1", "--references", h, "-q"],
    "approximations": lambda f, h, o: ["breaklines", f, o / "o.geojson", "--approximations", h, "-q"],
    "polygon": lambda f, h, o: ["crop", f, o / "o.laz", "--polygon", h, "-q"],
    "truth": lambda f, h, o: ["parts", f, o / "pa", "--truth", h, "-r", "1.2", "-q"],
    "pipeline": lambda f, h, o: ["run", h, "-i", f, "-o", o / "o.laz"],
}


@pytest.mark.parametrize("kind", list(HOSTILE_JSON))
@pytest.mark.parametrize("reader", list(CONFIG_COMMANDS))
def test_hostile_config_files_are_refused_in_one_line(cloud_file, tmp_path, run_cli, monkeypatch, reader, kind):
    monkeypatch.chdir(tmp_path)
    hostile = _hostile_file(tmp_path, kind, ".geojson" if reader in ("approximations", "polygon") else ".json")
    (tmp_path / "out").mkdir()
    argv = [str(a) for a in CONFIG_COMMANDS[reader](str(cloud_file), str(hostile), tmp_path / "out")]
    rc, _, err = run_cli(argv)
    one_line(rc, err)
    assert not any(p.is_file() for p in (tmp_path / "out").rglob("*")) and not (tmp_path / "MARKER").exists()


@pytest.mark.parametrize("spec", ["temp=__import__('os').system('touch MARKER')", "temp=1e999", "temp=nan",
                                  "ice=" + "9" * 5000, "x=1", "temp=80,temp=81"])
def test_hostile_load_cases_are_refused(cloud_file, tmp_path, run_cli, spec):
    rc, _, err = run_cli(["powerlines", str(cloud_file), str(tmp_path / "pl"), "--load-case", spec, "-q"])
    one_line(rc, err)
    rc, _, err = run_cli(["powerlines", str(cloud_file), str(tmp_path / "pl"), "--load-case", "temp=80",
                          "--conductor", spec.replace("temp", "mass") + ",area=1,diameter=1,modulus=1,alpha=1", "-q"])
    one_line(rc, err)
    assert not list(tmp_path.rglob("*.csv"))


@pytest.mark.parametrize("param", ["n_trees=__import__('os').system('touch MARKER')", "density=[1, 2]",
                                   'density={"__class__": "eval"}', "density=1e999", "seed=" + "9" * 5000,
                                   "density=" + "[" * 5000 + "]" * 5000])
def test_hostile_scene_parameters_are_refused(tmp_path, run_cli, monkeypatch, param):
    monkeypatch.chdir(tmp_path)
    rc, _, err = run_cli(["synth", "powerline", "s.laz", "-p", param])
    one_line(rc, err)
    assert not (tmp_path / "s.laz").exists() and not (tmp_path / "MARKER").exists()


# --------------------------------------------------------------------- the resume work folder
@pytest.fixture
def work_folder(cloud_file, tmp_path):
    """A finished chunked run's work folder, kept: (run again, work folder, victim folder)."""
    from lidarfx.tiles.engine import run_tiled

    opts = {"features": "density", "radii": [1.0], "neighbourhood": "sphere", "k": None, "scanner": None,
            "height": None, "convention": "default", "d_max": 0.1, "hist_bins": 10, "seed": 0}
    work = tmp_path / "work"
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("precious")
    counter = iter(range(100))

    def again(resume: bool = True):
        return run_tiled(str(cloud_file), tmp_path / f"o{next(counter)}.laz", "features", opts, chunk_size=12.0,
                         workers=1, resume=resume, work_dir=work, keep_work=True, progress=False)

    first = again(resume=False)
    assert first.chunks >= 4 and (work / "split" / "split.json").is_file()
    return again, work, victim


def test_resume_continues_an_untouched_work_folder(work_folder):
    again, work, _ = work_folder
    for p in (work / "done").glob("*.json"):
        p.unlink()
    run = again()
    assert run.resumed == 0 and run.chunks >= 4


@pytest.mark.parametrize("tamper", ["outside", "absolute", "types", "huge", "nan", "deep", "garbage", "points"])
def test_resume_refuses_a_tampered_split_record(work_folder, tamper):
    again, work, victim = work_folder
    path = work / "split" / "split.json"
    split = json.loads(path.read_text())
    bad = copy.deepcopy(split)
    if tamper == "outside":
        bad["chunks"][0]["name"] = os.path.relpath(victim, work / "out")  # ../../victim
    elif tamper == "absolute":
        bad["chunks"][0]["name"] = str(victim)
    elif tamper == "types":
        bad["chunks"][0]["i"] = "0; touch MARKER"
    elif tamper == "huge":
        bad["chunks"][0]["buffered"] = 10**30
    elif tamper == "points":
        bad["points"] = split["points"] + 1
    text = {"nan": json.dumps(split).replace(str(split["mins"][0]), "NaN", 1), "deep": "[" * 100_000 + "]" * 100_000,
            "garbage": "\x00\x01"}.get(tamper, json.dumps(bad))
    path.write_text(text)
    for p in (work / "done").glob("*.json"):
        p.unlink()  # every chunk runs again
    with pytest.raises(LidarfxError, match="split.json is damaged or was not written by lidarfx") as exc:
        again()
    assert "\n" not in str(exc.value)
    assert (victim / "keep.txt").read_text() == "precious" and sorted(p.name for p in victim.iterdir()) == ["keep.txt"]


@pytest.mark.parametrize("manifest", ['{"version": 1, "command": "__import__(\'os\')"}', "[" * 100_000, "\x00"])
def test_resume_refuses_a_foreign_manifest(work_folder, manifest):
    again, work, _ = work_folder
    (work / "manifest.json").write_text(manifest)
    with pytest.raises(LidarfxError, match="holds a run with other inputs or options"):
        again()
