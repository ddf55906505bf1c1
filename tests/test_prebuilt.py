"""The kernels shipped with the package (lidarfx._prebuilt, tools/build_kernels.py)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from lidarfx import _numba_cache, _prebuilt

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tools"))
import build_kernels  # noqa: E402


def _manifest(bundle=_prebuilt.BUNDLE):
    with zipfile.ZipFile(bundle) as zf:
        return json.loads(zf.read("manifest.json"))


def test_the_bundle_is_built_from_these_sources():
    """A kernel module edited since the bundle was built would make every first run compile for
    minutes (the bundle is then refused): rebuild it with `python tools/build_kernels.py`."""
    assert _prebuilt.BUNDLE.exists(), "no kernel bundle: run python tools/build_kernels.py"
    m = _manifest()
    sources = build_kernels.kernel_sources()
    assert m["sources"] == sources, "the kernel modules' imports changed: run python tools/build_kernels.py"
    assert m["digest"] == _prebuilt.sources_digest(sources), \
        "a kernel module changed since the bundle was built: run python tools/build_kernels.py"
    # the bundle holds the kernels of the feature engine, the index, ground, segmentation, rendering
    names = {f.split("-")[0] for files in m["files"].values() for f in files}
    for kernel in ("engine.point_features", "neighbors._radius_kernel", "neighbors._knn_kernel", "tin._walk",
                   "planes._grow", "splat._splat_kernel", "__init__._classify_kernel", "fastpredict._raw_scores"):
        assert kernel in names


def _bundle_with(tmp_path, **changes):
    """A copy of the shipped bundle with manifest fields changed."""
    src = _prebuilt.BUNDLE
    out = tmp_path / "kernels.zip"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "manifest.json":
                m = json.loads(data)
                m.update(changes)
                data = json.dumps(m).encode()
            zout.writestr(item, data)
    return out


@pytest.mark.skipif(not _prebuilt.BUNDLE.exists(), reason="no kernel bundle in this checkout")
@pytest.mark.parametrize("change, reason", [
    ({"digest": "0" * 64}, "the sources differ"),
    ({"numba": "0.0.1"}, "bundle for numba 0.0.1"),
    ({"python": "py27"}, "bundle for py27"),
    ({"triple": "aarch64-apple-darwin"}, "bundle for aarch64-apple-darwin"),
    ({"cpu_needs": ["no-such-feature"]}, "this processor lacks"),
])
def test_a_bundle_that_does_not_fit_is_refused(tmp_path, monkeypatch, change, reason):
    cpu = os.environ.get("NUMBA_CPU_NAME")
    assert _prebuilt.install(bundle=_bundle_with(tmp_path, **change)).startswith(reason)
    assert os.environ.get("NUMBA_CPU_NAME") == cpu  # nothing changed for numba


def test_off_switch_and_missing_bundle(tmp_path, monkeypatch):
    assert _prebuilt.install(bundle=tmp_path / "none.zip") == "no bundle"
    (tmp_path / "bad.zip").write_bytes(b"not a zip")
    assert _prebuilt.install(bundle=tmp_path / "bad.zip") == "unreadable bundle"
    monkeypatch.setenv("LIDARFX_PREBUILT", "0")
    assert _prebuilt.install().startswith("off")


def _fresh_run(tmp_path, code, **env):
    e = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    e.update(NUMBA_CACHE_DIR=str(tmp_path / "cache"), LIDARFX_COMPILE_NOTICE="1", **env)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900, env=e,
                          check=False)


def test_a_first_run_loads_the_shipped_kernels_and_compiles_nothing(tmp_path):
    """A fresh process on an empty numba cache: the bundle is installed into it and the feature
    engine, the index and the renderer run without compiling (the compile notice stays silent)."""
    code = (
        "import numpy as np, lidarfx, lidarfx._prebuilt as pb\n"
        "from numba.core import event\n"
        "n = []\n"
        "class L(event.Listener):\n"
        "    def on_start(self, ev): n.append(ev.data['dispatcher'].py_func.__qualname__)\n"
        "    def on_end(self, ev): pass\n"
        "event.register('numba:compile', L())\n"
        "from lidarfx.features import compute_features\n"
        "pc = lidarfx.PointCloud(np.random.default_rng(0).uniform(0, 5, (2000, 3)))\n"
        "f = compute_features(pc, 'eigen,plane', radius=1.0, progress=False)\n"
        "print(pb.status); print(sorted(set(n)))\n"
    )
    r = _fresh_run(tmp_path, code)
    assert r.returncode == 0, r.stderr[-1500:]
    status, compiled = r.stdout.strip().splitlines()[-2:]
    if not status.startswith("installed"):
        pytest.skip(f"the bundle does not fit this machine or checkout: {status}")
    assert compiled == "[]"
    assert _numba_cache.NOTICE not in r.stderr
    # a second process finds the kernels where they were put
    r2 = _fresh_run(tmp_path, code)
    assert r2.stdout.strip().splitlines()[-2:] == ["current", "[]"]


def test_the_checks_agree_with_numba_without_importing_it(tmp_path, monkeypatch):
    """The install decides without importing numba; what it reads must be what numba would say."""
    import llvmlite.binding as ll
    import numba
    from types import SimpleNamespace

    from numba.core.caching import CacheImpl

    assert _prebuilt.numba_version() == numba.__version__
    assert _prebuilt.process_triple() == ll.get_process_triple()
    have = {k for k, v in ll.get_host_cpu_features().items() if v}
    for feature in _prebuilt.CPU_NEEDS:
        assert _prebuilt.host_supports((feature,)) == (feature in have), feature
    fake = SimpleNamespace(__code__=SimpleNamespace(co_firstlineno=1))

    def numba_path(py_file):
        for cls in CacheImpl._locator_classes:
            loc = cls.from_function(fake, str(py_file))
            if loc is not None:
                return Path(loc.get_cache_path())

    src = tmp_path / "pkg" / "mod.py"
    src.parent.mkdir()
    src.write_text("x = 1\n")
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    assert _prebuilt.cache_path(src) == numba_path(src) == src.parent / "__pycache__"
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "nbcache"))
    assert _prebuilt.cache_path(src) == numba_path(src) == tmp_path / "nbcache" / _prebuilt.cache_subpath(src)


def test_importing_lidarfx_does_not_import_numba():
    """`lidarfx --help` and scripts that only read files stay quick (numba takes ~0.5 s to import)."""
    r = subprocess.run([sys.executable, "-c", "import sys, lidarfx; print('numba' in sys.modules)"],
                       capture_output=True, text=True, timeout=120, check=True)
    assert r.stdout.strip() == "False"
