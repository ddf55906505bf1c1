"""The guard that keeps numba's on-disk cache in step with edited sources (lidarfx._numba_cache)."""
from __future__ import annotations

import os

from lidarfx import _numba_cache


def _tree(tmp_path):
    root = tmp_path / "pkg"
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "__pycache__").mkdir()
    (root / "a.py").write_text("x = 1\n")
    (root / "sub" / "b.py").write_text("y = 2\n")
    return root


def _cache_files(root):
    return sorted(p.name for p in root.rglob("__pycache__/*.nb[ic]"))


def _plant(root):
    for d in (root / "__pycache__", root / "sub" / "__pycache__"):
        (d / "k-1.py311.nbi").write_bytes(b"index")
        (d / "k-1.py311.1.nbc").write_bytes(b"code")
    (root / "__pycache__" / "a.cpython-311.pyc").write_bytes(b"pyc")  # not numba's: never touched


def test_stale_kernels_are_deleted_only_when_a_source_changes(tmp_path):
    root = _tree(tmp_path)
    stamp = root / "__pycache__" / "key"
    _plant(root)
    assert _numba_cache.check(root, stamp) is True  # no record yet: whatever is cached is suspect
    assert _cache_files(root) == [] and (root / "__pycache__" / "a.cpython-311.pyc").exists()
    _plant(root)
    assert _numba_cache.check(root, stamp) is False  # nothing changed: the cache stays
    assert len(_cache_files(root)) == 4
    st = (root / "sub" / "b.py").stat()
    os.utime(root / "sub" / "b.py", ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # a callee edited
    assert _numba_cache.check(root, stamp) is True
    assert _cache_files(root) == []
    _plant(root)
    (root / "c.py").write_text("z = 3\n")  # a new module counts too
    assert _numba_cache.check(root, stamp) is True and _cache_files(root) == []


def test_an_unwritable_place_is_left_alone(tmp_path):
    root = _tree(tmp_path)
    _plant(root)
    blocked = tmp_path / "file"
    blocked.write_text("")
    assert _numba_cache.check(root, blocked / "key") is False  # the record cannot be written: no exception


def test_the_package_is_in_step_after_import():
    import lidarfx  # noqa: F401  (the import ran the check)

    assert _numba_cache.STAMP.read_text() == _numba_cache.fingerprint()


def _kernels():
    """Every numba-compiled function of the package: name -> (module path, parallel?, names it calls)."""
    import ast
    from pathlib import Path

    import lidarfx

    out = {}
    for path in Path(lidarfx.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            for dec in node.decorator_list:
                text = ast.unparse(dec)
                if "jit" in text:
                    calls = {c.func.id if isinstance(c.func, ast.Name) else getattr(c.func, "attr", None)
                             for c in ast.walk(node) if isinstance(c, ast.Call)}
                    out.setdefault(node.name, []).append((str(path), "parallel=True" in text, calls))
    return out


def test_parallel_kernels_are_threads_over_nogil_kernels():
    """Parallelism comes from threads over nogil kernels (lidarfx._parallel), not numba's
    ``parallel=True``: its parfor passes tripled the compile time of a first run, and a cached
    kernel that calls a parallel one segfaults when loaded from numba's disk cache (numba #8578).
    The one exception, the kNN kernel (three times faster per query with numba's parallel
    pipeline), is called from Python only.  Every kernel handed to ``parallel.run`` must release
    the GIL, or the threads take turns."""
    import ast
    import re
    from pathlib import Path

    import lidarfx

    kernels = _kernels()
    assert len(kernels) > 20
    parallel = {name for name, defs in kernels.items() if any(p for _, p, _ in defs)}
    assert parallel == {"_knn_kernel"}
    assert [f"{path}: {name}" for name, defs in kernels.items() for path, _, calls in defs if calls & parallel] == []
    nogil = set()
    for path in Path(lidarfx.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and any("nogil=True" in ast.unparse(d) for d in node.decorator_list):
                nogil.add(node.name)
    run_targets = set()
    for path in Path(lidarfx.__file__).parent.rglob("*.py"):
        run_targets |= set(re.findall(r"parallel\.run\(\s*(\w+)", path.read_text()))
    assert len(run_targets) >= 8
    assert run_targets - nogil == set()


def test_one_point_index_from_the_disk_cache():
    """The real path: two fresh processes build the index of one point (its z column is
    C-contiguous: a kernel specialisation of its own); the second loads the kernels from disk."""
    import subprocess
    import sys

    code = ("import numpy as np; from lidarfx.neighbors import NeighborIndex; "
            "i = NeighborIndex(np.array([[1.0, 2.0, 3.0]]), 0.5); print(i.order.tolist())")
    for _ in range(2):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False)
        assert r.returncode == 0, r.stderr[-500:]
        assert r.stdout.strip() == "[0]"


def test_a_cold_cache_prints_one_notice_a_warm_one_none(tmp_path):
    """The first run on a machine compiles kernels for a while: the CLI says so in one line,
    once per process, and says nothing when the kernels come from the disk cache."""
    import subprocess
    import sys

    import numpy as np

    from lidarfx import _numba_cache

    cloud = tmp_path / "c.xyz"
    rng = np.random.default_rng(0)
    np.savetxt(cloud, rng.uniform(0, 5, (300, 3)))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), LIDARFX_COMPILE_NOTICE="1", LIDARFX_PREBUILT="0")
    cmd = [sys.executable, "-m", "lidarfx", "render", str(cloud), str(tmp_path / "t.png"), "--size", "200x160",
           "--shading", "none", "-q"]
    errs = []
    for i in range(2):
        (tmp_path / "t.png").unlink(missing_ok=True)
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, check=False)
        assert r.returncode == 0, r.stderr[-500:]
        errs.append(r.stderr)
    assert errs[0].count(_numba_cache.NOTICE) == 1 and errs[0].strip() == _numba_cache.NOTICE
    assert errs[1] == ""


def test_a_numba_cache_dir_is_kept_in_step_too(tmp_path, monkeypatch):
    """With NUMBA_CACHE_DIR set, numba keeps the kernels there: an edit in another module must clear
    them as it clears the __pycache__ folders (before, they stayed and computed with stale code)."""
    root = _tree(tmp_path)
    cache = tmp_path / "numba-cache"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    folders = _numba_cache._user_cache_folders(root, cache)
    assert len(folders) == 2
    for d in folders:
        d.mkdir(parents=True)
        (d / "k-1.py311.nbi").write_bytes(b"index")
    other = cache / "elsewhere_0123"  # another package's kernels: never touched
    other.mkdir()
    (other / "k-1.py311.nbi").write_bytes(b"index")
    monkeypatch.setattr(_numba_cache, "STAMP", root / "__pycache__" / "key")
    assert _numba_cache.check(root) is True
    assert not any(any(d.glob("*.nbi")) for d in folders) and (other / "k-1.py311.nbi").exists()
    for d in folders:
        (d / "k-1.py311.nbi").write_bytes(b"index")
    assert _numba_cache.check(root) is False  # nothing changed: both records current
    assert all((d / "k-1.py311.nbi").exists() for d in folders)
    (root / "a.py").write_text("x = 2  # edited\n")
    assert _numba_cache.check(root) is True
    assert not any(any(d.glob("*.nbi")) for d in folders)
