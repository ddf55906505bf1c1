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

The checks do not import numba (``import lidarfx`` stays light): numba's version is read from its
``_version.py``, the processor's features from ``/proc/cpuinfo``, and the cache folder follows
numba's own order (``NUMBA_CACHE_DIR``, the module's ``__pycache__``, the user cache folder), which
``tests/test_prebuilt.py`` compares with numba's locators.
"""
from __future__ import annotations

import hashlib
import json
import os
import pickle
import platform
import re
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
BUNDLE = ROOT / "data" / "kernels.zip"
CPU_NAME = "x86-64-v3"
# the features LLVM's x86-64-v3 model assumes (x86-64-v2 + AVX, AVX2, BMI1/2, F16C, FMA, LZCNT, MOVBE, XSAVE)
CPU_NEEDS = ("sse3", "ssse3", "sse4.1", "sse4.2", "popcnt", "cx16", "avx", "avx2", "bmi", "bmi2", "f16c", "fma",
             "lzcnt", "movbe", "xsave")
# LLVM's feature names -> the Linux kernel's (/proc/cpuinfo flags) where they differ
CPUINFO_NAMES = {"sse3": "pni", "sse4.1": "sse4_1", "sse4.2": "sse4_2", "bmi": "bmi1", "lzcnt": "abm"}

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
    """True when the processor has every feature of ``needs`` (LLVM's names), read from
    ``/proc/cpuinfo`` (False where there is none: the bundle is for Linux only)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            flags = next((line.split(":", 1)[1].split() for line in f if line.startswith("flags")), [])
    except OSError:
        return False
    have = set(flags)
    return all(CPUINFO_NAMES.get(f, f) in have for f in needs)


def process_triple() -> str:
    """The target triple LLVM reports for this process (the bundle records the one it was built on)."""
    if sys.platform.startswith("linux"):
        return f"{platform.machine()}-unknown-linux-gnu"
    return f"{platform.machine()}-{sys.platform}"


def numba_version() -> str | None:
    """numba's version without importing it (its ``_version.py``), or None when numba is missing."""
    mod = sys.modules.get("numba")
    if mod is not None:
        return getattr(mod, "__version__", None)
    import importlib.util

    try:
        spec = importlib.util.find_spec("numba")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.origin:
        return None
    try:
        text = (Path(spec.origin).parent / "_version.py").read_text(encoding="utf-8")
    except OSError:
        return None
    m = re.search(r'"version":\s*"([^"]+)"', text)
    return m.group(1) if m else None


def _numba_cache_dir() -> str:
    """numba's ``config.CACHE_DIR`` (its own value once numba is imported, else the environment's)."""
    mod = sys.modules.get("numba.core.config")
    if mod is not None:
        return getattr(mod, "CACHE_DIR", "") or ""
    return os.environ.get("NUMBA_CACHE_DIR", "")


def _user_cache_dir() -> Path:
    """numba's user-wide cache folder on Linux (``appdirs.user_cache_dir("numba")``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")) / "numba"


def cache_subpath(py_file: Path) -> str:
    """The folder numba names after the folder of ``py_file`` inside a cache directory."""
    folder = os.path.dirname(os.path.abspath(py_file))
    return f"{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}"


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
        return True
    except OSError:
        return False


def cache_path(py_file: Path) -> Path | None:
    """The folder numba's cache uses for the kernels of ``py_file``, in numba's order: under
    ``NUMBA_CACHE_DIR`` when set, else the module's ``__pycache__`` when writable, else the
    user cache folder (None: nowhere writable).  Creates the folder, as numba does."""
    candidates = []
    if _numba_cache_dir():
        candidates.append(Path(_numba_cache_dir()) / cache_subpath(py_file))
    candidates += [py_file.parent / "__pycache__", _user_cache_dir() / cache_subpath(py_file)]
    return next((c for c in candidates if _writable(c)), None)


def _index_is_current(path: Path, version: str, digest: bytes) -> bool:
    """True when numba's index at ``path`` is of numba ``version`` and of the source whose SHA-256
    is ``digest`` (numba pickles its version string, then (source SHA-256, overloads); the digest
    is looked for in the bytes so that the overloads, numba objects, need not be unpickled)."""
    try:
        with open(path, "rb") as f:
            if pickle.load(f) != version:
                return False
            return digest in f.read()
    except Exception:
        return False


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    tmp.replace(path)


def _codegen_started() -> bool:
    """True when numba's CPU code generator exists already (its processor can no longer change)."""
    if "numba.core.registry" not in sys.modules:
        return False
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
    version = numba_version()
    if manifest.get("numba") != version:
        return f"bundle for numba {manifest.get('numba')}, not {version}"
    if manifest.get("python") != python_tag():
        return f"bundle for {manifest.get('python')}, not {python_tag()}"
    if manifest.get("triple") != process_triple():
        return f"bundle for {manifest.get('triple')}, not {process_triple()}"
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
    if "numba.core.config" in sys.modules:  # numba read its settings already
        sys.modules["numba.core.config"].reload_config()
    written = 0
    try:
        for module, files in manifest["files"].items():
            source = root / module
            dest = cache_path(source)
            if dest is None:
                continue
            digest = hashlib.sha256(source.read_bytes()).digest()
            for index in [f for f in files if f.endswith(".nbi")]:
                if (dest / index).exists() and _index_is_current(dest / index, version, digest):
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
