"""Kernels compiled ahead of time, shipped with the package, for a first run without compiling.

numba compiles lidarfx's kernels on first use and keeps them in its disk cache; a first run on a
new machine would spend minutes compiling (the whole demo: about 3 minutes on 2 cores).  The
package therefore carries ``data/kernels.zip``: numba's own cache files of every kernel the
demo and the common commands use, compiled for the ``x86-64-v3`` instruction set (AVX2 and FMA:
the x86-64 processors of about 2015 onwards) by ``tools/build_kernels.py``.

:func:`install` runs when lidarfx is imported.  When everything matches — the numba version,
the Python version, the platform, a processor with every x86-64-v3 feature, and the sources the
kernels were compiled from (a SHA-256 over the kernel modules and every package module they
import) — it copies the files into the cache directory numba uses for each module (its
``__pycache__``, or ``NUMBA_CACHE_DIR``) unless a current copy is there already, and sets
``NUMBA_CPU_NAME=x86-64-v3`` / ``NUMBA_CPU_FEATURES=`` for the process so that numba looks
them up (a kernel the bundle lacks is then compiled for the same target).  numba itself checks
each file against its source module (SHA-256 of the module's text) before it loads it.

When anything differs (an edited checkout, another numba, an ARM or older processor, a
``NUMBA_CPU_NAME`` of the user's own, ``LIDARFX_PREBUILT=0``) nothing is copied and numba
compiles for the host processor as usual.
"""
from __future__ import annotations

import hashlib
import json
import os
import pickle
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
BUNDLE = ROOT / "data" / "kernels.zip"
CPU_NAME = "x86-64-v3"
# the features LLVM's x86-64-v3 model assumes (x86-64-v2 + AVX, AVX2, BMI1/2, F16C, FMA, LZCNT, MOVBE, XSAVE)
CPU_NEEDS = ("sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "cx16", "avx", "avx2", "bmi", "bmi2", "f16c", "fma",
             "lzcnt", "movbe", "xsave")

status = "not tried"
"""What :func:`install` did in this process (for ``lidarfx info --kernels`` style diagnostics and tests)."""


def sources_digest(files: list[str], root: Path = ROOT) -> str:
    """SHA-256 over the (path, text) of ``files`` (package-relative, in the given order)."""
    h = hashlib.sha256()
    for rel in files:
        h.update(rel.encode() + b"\0")
        h.update((root / rel).read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def python_tag() -> str:
    return f"py{sys.version_info[0]}{sys.version_info[1]}"


def host_supports(needs=CPU_NEEDS) -> bool:
    """True when the processor has every feature of ``needs`` (LLVM's names)."""
    try:
        import llvmlite.binding as ll

        have = {k for k, v in ll.get_host_cpu_features().items() if v}
    except Exception:  # no feature map on this platform
        return False
    return all(f in have for f in needs)


def _locator_cache_path(py_file: Path) -> Path | None:
    """The directory numba's cache uses for kernels of ``py_file`` (its own locator order)."""
    from types import SimpleNamespace

    from numba.core.caching import CacheImpl

    fake = SimpleNamespace(__code__=SimpleNamespace(co_firstlineno=1))
    for cls in CacheImpl._locator_classes:
        try:
            loc = cls.from_function(fake, str(py_file))
        except Exception:
            continue
        if loc is not None:
            return Path(loc.get_cache_path())
    return None


def _index_is_current(path: Path, digest: bytes) -> bool:
    """True when numba's index at ``path`` is of this numba and of the source whose SHA-256 is ``digest``."""
    import numba

    try:
        with open(path, "rb") as f:
            if pickle.load(f) != numba.__version__:
                return False
            stamp, _ = pickle.loads(f.read())
    except Exception:
        return False
    return stamp == digest


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)


def _codegen_started() -> bool:
    """True when numba's CPU code generator exists already (its processor can no longer change)."""
    from numba.core.registry import cpu_target

    return "_toplevel_target_context" in vars(cpu_target)


def install(root: Path = ROOT, bundle: Path | None = None) -> str:
    """Put the shipped kernels where numba looks for them; returns (and keeps in :data:`status`)
    what happened: ``installed N`` / ``current`` or the reason nothing was done."""
    global status
    status = _install(root, BUNDLE if bundle is None else bundle)
    return status


def _install(root: Path, bundle: Path) -> str:
    if os.environ.get("LIDARFX_PREBUILT", "1") == "0":
        return "off (LIDARFX_PREBUILT=0)"
    if not bundle.exists():
        return "no bundle"
    try:
        zf = zipfile.ZipFile(bundle)
        manifest = json.loads(zf.read("manifest.json"))
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        return "unreadable bundle"
    import numba
    import llvmlite.binding as ll

    if manifest.get("numba") != numba.__version__:
        return f"bundle for numba {manifest.get('numba')}, not {numba.__version__}"
    if manifest.get("python") != python_tag():
        return f"bundle for {manifest.get('python')}, not {python_tag()}"
    if manifest.get("triple") != ll.get_process_triple():
        return f"bundle for {manifest.get('triple')}, not {ll.get_process_triple()}"
    for var, want in (("NUMBA_CPU_NAME", manifest["cpu_name"]), ("NUMBA_CPU_FEATURES", manifest["cpu_features"])):
        if os.environ.get(var, want) != want:
            return f"{var} is set to {os.environ[var]!r}"
    if not host_supports(tuple(manifest.get("cpu_needs", CPU_NEEDS))):
        return f"this processor lacks part of {manifest['cpu_name']}"
    try:
        if sources_digest(manifest["sources"], root) != manifest["digest"]:
            return "the sources differ from the bundle's"
    except OSError:
        return "the sources differ from the bundle's"
    if _codegen_started() and os.environ.get("NUMBA_CPU_NAME") != manifest["cpu_name"]:
        return "numba compiled code before lidarfx was imported"
    os.environ["NUMBA_CPU_NAME"] = manifest["cpu_name"]
    os.environ["NUMBA_CPU_FEATURES"] = manifest["cpu_features"]
    numba.config.reload_config()
    written = 0
    try:
        for module, files in manifest["files"].items():
            source = root / module
            dest = _locator_cache_path(source)
            if dest is None:
                continue
            digest = hashlib.sha256(source.read_bytes()).digest()
            for index in [f for f in files if f.endswith(".nbi")]:
                if (dest / index).exists() and _index_is_current(dest / index, digest):
                    continue
                stem = index[: -len(".nbi")]
                for name in [f for f in files if f == index or (f.startswith(stem + ".") and f.endswith(".nbc"))]:
                    if name != index:
                        _write_atomic(dest / name, zf.read(f"{module}/{name}"))
                _write_atomic(dest / index, zf.read(f"{module}/{index}"))  # last: the data files exist
                written += 1
    except OSError as exc:  # an unwritable cache: numba compiles as usual
        return f"cache not writable ({exc.strerror or exc})"
    return f"installed {written}" if written else "current"
