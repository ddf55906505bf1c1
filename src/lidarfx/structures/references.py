"""Reference signatures of the ideal structures (ISPRS 2016; docs/structures.md), generated numerically.

A *signature* of a point is ``(e1, e2, e3, centroid_offset)`` of its sphere
neighbourhood: the covariance eigenvalues normalised by their sum and the
distance of the neighbourhood centroid from the point divided by the radius
(docs/features.md §3, docs/conventions.md "Ideal structures").  Both are invariant to position, rotation and scale.

The references are made the way ISPRS 2016 makes its training set: the ideal
structures of :mod:`lidarfx.synth` (plane, plane border, edge, corner, line,
line end, volume) are sampled at several densities and noise levels with a
random rotation each, and the signature of every sample's query point is
computed with lidarfx's own neighbourhood code
(:func:`lidarfx.features.api.feature_arrays`).  A *prototype* is one structure
(edges: one dihedral angle band) and holds, per *count level* (expected number
of points in the sphere), the mean and standard deviation of the signature
over the samples, the mean eigenvalues λ/R² and the median neighbour count.
The classifier interpolates between count levels by the point's own neighbour
count, so the spread it compares against is that of neighbourhoods as sparse or
as dense as the point's.

The package ships the references made by :func:`generate_references` with its
defaults (``lidarfx/data/structure_references.json``);
``lidarfx eigenclass-references OUT.json`` makes them again (or with other
settings).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import LidarfxError, check_int, check_seed

SIGNATURE = ("e1", "e2", "e3", "centroid_offset")
"""The signature's components, in order."""

COUNT_LEVELS = (6, 12, 24, 48, 96, 192, 384, 768, 1536)
"""Expected points in the sphere of the reference samples (one level each)."""
NOISE_LEVELS = (0.0, 0.01, 0.02, 0.04)
"""Gaussian σ of the reference samples as a share of the radius; the samples of a level
cycle through them."""
EDGE_ANGLES = (60.0, 75.0, 90.0, 105.0, 120.0, 135.0)
"""Dihedral angles (degrees) of the edge prototypes; each samples its angle ± ANGLE_JITTER."""
ANGLE_JITTER = 7.5
SAMPLES = 200
"""Samples per prototype and count level."""
EXTENT = 1.1
"""Half-width of the sampled cube in radii (covers the sphere and a noise margin)."""
SPACING = 3.0
"""Distance (radii) between the samples laid out side by side in one cloud."""

STD_FLOOR = (0.01, 0.01, 0.003, 0.02)
"""Smallest standard deviation used per signature component: a line's e2 and e3 spread by
10⁻⁴ only, which would make any real wire (noise, sag) infinitely far from it."""

DEFAULT_FILE = Path(__file__).resolve().parent.parent / "data" / "structure_references.json"
FORMAT = "lidarfx structure references"
VERSION = 1
MAX_FILE_BYTES = 20_000_000
"""A references file larger than this is refused before it is read."""

STRUCTURES = ("plane", "plane_border", "edge", "corner", "line", "line_end", "volume")


@dataclass
class References:
    """Reference signatures: prototypes × count levels × signature components.

    ``structure`` names the class of each prototype, ``angle`` its dihedral
    angle (edges; else ``None``), ``counts`` the count level of each level,
    ``n_median`` (P, L) the median neighbour count of the samples, ``mean`` and
    ``std`` (P, L, 4) the signature statistics, ``lambda_r2`` (P, L, 3) the
    mean eigenvalues divided by R², ``parameters`` how they were generated.
    """

    names: list[str]
    structure: list[str]
    angle: list[float | None]
    counts: np.ndarray
    n_median: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    lambda_r2: np.ndarray
    parameters: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------ tables
    def tables(self, kind: str = "trained", weighting: str = "structure"):
        """Arrays for the classifier: ``(class_id[P], log_n[P, L], mean[P, L, 4], std[P, L, 4])``.

        ``kind="trained"`` uses the generated means, ``"analytic"`` the closed forms of
        the ideal structures (the same at every level).  ``weighting="structure"``
        uses each prototype's own spread (floored at :data:`STD_FLOOR`),
        ``"uniform"`` one spread per count level shared by every prototype and
        component (a plain Euclidean distance, scaled so the reject threshold keeps
        its meaning).
        """
        from ..synth.structures import STRUCTURE_IDS, analytic_centroid_offset, analytic_eigenvalues

        if kind not in ("trained", "analytic"):
            raise LidarfxError(f"references must be 'trained', 'analytic' or a file, got {kind!r}")
        if weighting not in ("structure", "uniform"):
            raise LidarfxError(f"weighting must be 'structure' or 'uniform', got {weighting!r}")
        mean = self.mean.astype(np.float64).copy()
        if kind == "analytic":
            for p, (s, a) in enumerate(zip(self.structure, self.angle)):
                lam = np.asarray(analytic_eigenvalues(s, 90.0 if a is None else a))
                sig = np.r_[lam / lam.sum(), analytic_centroid_offset(s, 90.0 if a is None else a)]
                mean[p] = sig
        std = np.maximum(self.std.astype(np.float64), np.asarray(STD_FLOOR))
        if weighting == "uniform":
            per_level = std.mean(axis=(0, 2))  # (L,)
            std = np.broadcast_to(per_level[None, :, None], std.shape).copy()
        cid = np.array([STRUCTURE_IDS[s] for s in self.structure], np.int32)
        log_n = np.log(np.maximum(self.n_median.astype(np.float64), 1.0))
        return cid, np.ascontiguousarray(log_n), np.ascontiguousarray(mean), np.ascontiguousarray(std)

    # ------------------------------------------------------------ files
    def to_json(self) -> dict[str, Any]:
        def r(a):
            return [float(f"{v:.6g}") for v in np.asarray(a, dtype=np.float64).ravel()]

        protos = []
        for p, name in enumerate(self.names):
            levels = [
                {"count": int(self.counts[l]), "n_median": float(self.n_median[p, l]), "mean": r(self.mean[p, l]),
                 "std": r(self.std[p, l]), "lambda_r2": r(self.lambda_r2[p, l])}
                for l in range(len(self.counts))
            ]
            protos.append({"name": name, "structure": self.structure[p], "angle": self.angle[p], "levels": levels})
        return {"format": FORMAT, "version": VERSION, "signature": list(SIGNATURE),
                "parameters": self.parameters, "prototypes": protos}

    def save(self, path: str | os.PathLike) -> Path:
        """Write the references as JSON (atomically)."""
        from .._atomic import atomic_path

        text = json.dumps(self.to_json(), indent=1)
        with atomic_path(path) as tmp:
            tmp.write_text(text + "\n", encoding="utf-8")
        return Path(path)

    @classmethod
    def from_json(cls, doc: Any, where: str = "references") -> "References":
        """Build from the dict of :meth:`to_json`; a one-line :class:`LidarfxError` on anything wrong."""
        def bad(msg: str) -> LidarfxError:
            return LidarfxError(f"{where}: {msg}")

        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise bad(f"not a lidarfx structure references file (no \"format\": \"{FORMAT}\")")
        if doc.get("version") != VERSION:
            raise bad(f"references version {doc.get('version')!r} is not supported (this lidarfx reads {VERSION})")
        if doc.get("signature") != list(SIGNATURE):
            raise bad(f"signature must be {list(SIGNATURE)}")
        protos = doc.get("prototypes")
        if not isinstance(protos, list) or not protos:
            raise bad("no prototypes")
        names, structs, angles, counts = [], [], [], None
        nmed, mean, std, lam = [], [], [], []
        for i, pr in enumerate(protos):
            if not isinstance(pr, dict):
                raise bad(f"prototype {i} is not an object")
            s = pr.get("structure")
            if s not in STRUCTURES:
                raise bad(f"prototype {i}: structure must be one of {', '.join(STRUCTURES)}, got {s!r}")
            a = pr.get("angle")
            if s == "edge":
                if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 < a <= 180:
                    raise bad(f"prototype {i}: an edge needs an angle in (0, 180], got {a!r}")
                a = float(a)
            else:
                a = None
            levels = pr.get("levels")
            if not isinstance(levels, list) or not levels:
                raise bad(f"prototype {i}: no levels")
            try:
                c = [check_int("count", lv["count"], 1, 10**9) for lv in levels]
                nm = [float(lv["n_median"]) for lv in levels]
                mu = [[float(v) for v in lv["mean"]] for lv in levels]
                sd = [[float(v) for v in lv["std"]] for lv in levels]
                lm = [[float(v) for v in lv.get("lambda_r2", [math.nan] * 3)] for lv in levels]
            except (KeyError, TypeError, ValueError, LidarfxError):
                raise bad(f"prototype {i}: every level needs count (a whole number >= 1), n_median, mean and std numbers") from None
            if counts is None:
                counts = c
            elif c != counts:
                raise bad(f"prototype {i}: count levels {c} differ from the first prototype's {counts}")
            if any(len(m) != len(SIGNATURE) for m in mu + sd) or any(len(m) != 3 for m in lm):
                raise bad(f"prototype {i}: mean and std need {len(SIGNATURE)} values, lambda_r2 3")
            arr = np.array(mu + sd, dtype=np.float64)
            if not np.isfinite(arr).all() or (np.array(sd) < 0).any():
                raise bad(f"prototype {i}: mean and std must be finite, std >= 0")
            if not all(v >= 1 and math.isfinite(v) for v in nm) or any(b <= a_ for a_, b in zip(nm, nm[1:])):
                raise bad(f"prototype {i}: n_median must be >= 1 and increase from level to level")
            names.append(str(pr.get("name", s)))
            structs.append(s)
            angles.append(a)
            nmed.append(nm)
            mean.append(mu)
            std.append(sd)
            lam.append(lm)
        params = doc.get("parameters") if isinstance(doc.get("parameters"), dict) else {}
        return cls(names, structs, angles, np.asarray(counts, np.int64), np.asarray(nmed), np.asarray(mean),
                   np.asarray(std), np.asarray(lam), params)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "References":
        """Read a references file (JSON of :meth:`save`)."""
        p = Path(path)
        if not p.is_file():
            raise LidarfxError(f"references file not found: {p}")
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise LidarfxError(f"{p}: {size:,} bytes is too large for a references file (at most {MAX_FILE_BYTES:,})")
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:  # huge integers, deep nesting too
            raise LidarfxError(f"{p}: not a JSON file ({' '.join(str(exc).split())[:200]})") from None
        return cls.from_json(doc, str(p))


_DEFAULT: References | None = None


def default_references() -> References:
    """The references shipped with lidarfx (generated with the defaults of :func:`generate_references`)."""
    global _DEFAULT
    if _DEFAULT is None:
        _DEFAULT = References.load(DEFAULT_FILE)
    return _DEFAULT


def resolve_references(references: Any) -> tuple[References, str]:
    """``(References, kind)`` of a ``references`` argument: ``"trained"`` / ``"analytic"``
    (the shipped file), a path, or a :class:`References`."""
    if isinstance(references, References):
        return references, "trained"
    if isinstance(references, str) and references in ("trained", "analytic"):
        return default_references(), references
    if isinstance(references, (str, os.PathLike)):
        return References.load(references), "trained"
    raise LidarfxError(f"references must be 'trained', 'analytic', a file or References, got {type(references).__name__}")


# ------------------------------------------------------------------ generation
def prototype_specs(edge_angles: Sequence[float] = EDGE_ANGLES) -> list[tuple[str, str, float | None]]:
    """``(name, structure, angle)`` of every prototype, in file order."""
    out: list[tuple[str, str, float | None]] = []
    for s in STRUCTURES:
        if s == "edge":
            out += [(f"edge_{a:g}", "edge", float(a)) for a in edge_angles]
        else:
            out.append((s, s, None))
    return out


def sample_signatures(structure: str, count: float, *, angle: float | None = None, noise: Sequence[float] = NOISE_LEVELS,
                      samples: int = SAMPLES, angle_jitter: float = ANGLE_JITTER, sampling: str = "random",
                      seed: Any = 0) -> dict[str, np.ndarray]:
    """Signatures of ``samples`` randomly rotated ideal ``structure`` samples with ``count``
    expected points in the unit sphere (noise cycling through ``noise``, σ in radii;
    ``sampling`` as in :mod:`lidarfx.synth`: ``"random"`` or ``"grid"``).

    Returns ``signature`` (samples, 4), ``lambda_r2`` (samples, 3) and ``n`` (samples,)
    — the neighbour count of each sample's query point.  ``seed`` is anything
    :class:`numpy.random.SeedSequence` takes (an int or a list of ints).
    """
    from .. import synth
    from ..features.api import feature_arrays

    rng = np.random.default_rng(np.random.SeedSequence(seed))
    density = synth.density_for_count(structure, count)
    parts, q = [], np.zeros((samples, 3))
    for i in range(samples):
        kw: dict[str, Any] = dict(radius=1.0, density=density, noise=float(noise[i % len(noise)]), rotation="random",
                                  extent=EXTENT, sampling=sampling, seed=int(rng.integers(2**31)))
        if structure == "edge":
            a = float(angle if angle is not None else 90.0) + float(rng.uniform(-angle_jitter, angle_jitter))
            kw["angle"] = min(max(a, 1.0), 180.0)
        xyz = synth.generate(structure, **kw).xyz
        q[i, 0] = i * SPACING
        parts.append(xyz + q[i])
    f = feature_arrays(np.vstack(parts), ["eigenvalue1", "eigenvalue2", "eigenvalue3", "centroid_offset", "n_neighbours"],
                       radius=1.0, query_xyz=q, progress=False)
    lam = np.c_[f["eigenvalue1"], f["eigenvalue2"], f["eigenvalue3"]].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = lam / lam.sum(axis=1, keepdims=True)
    return {"signature": np.c_[e, f["centroid_offset"].astype(np.float64)], "lambda_r2": lam,
            "n": f["n_neighbours"].astype(np.float64)}


def generate_references(*, counts: Sequence[int] = COUNT_LEVELS, noise: Sequence[float] = NOISE_LEVELS,
                        edge_angles: Sequence[float] = EDGE_ANGLES, samples: int = SAMPLES,
                        angle_jitter: float = ANGLE_JITTER, sampling: str = "random", seed: int = 0,
                        progress: bool | None = None) -> References:
    """Generate the reference signatures (see the module docstring).

    Every (prototype, level) has its own random stream
    (``SeedSequence([seed, prototype, level])``), so one entry can be made again
    on its own with :func:`sample_signatures`.  The defaults make the shipped
    references (about a minute on 2 cores).
    """
    from .. import __version__
    from ..progress import bar, wanted

    counts = [check_int("count level", c, 3, 100_000) for c in counts]
    if not counts or any(b <= a for a, b in zip(counts, counts[1:])):
        raise LidarfxError(f"count levels must increase, got {counts}")
    noise = [float(v) for v in noise]
    if not noise or not all(0 <= v <= 0.5 for v in noise):
        raise LidarfxError(f"noise levels are shares of the radius in [0, 0.5], got {noise}")
    edge_angles = [float(a) for a in edge_angles]
    if not edge_angles or not all(0 < a <= 180 for a in edge_angles):
        raise LidarfxError(f"edge angles must be in (0, 180] degrees, got {edge_angles}")
    if not 0 <= angle_jitter <= 90:
        raise LidarfxError(f"angle jitter must be in [0, 90] degrees, got {angle_jitter}")
    samples = check_int("samples", samples, 2, 100_000)
    seed = check_seed(seed)
    if sampling not in ("random", "grid"):
        raise LidarfxError(f"sampling must be 'random' or 'grid', got {sampling!r}")
    specs = prototype_specs(edge_angles)
    P, L = len(specs), len(counts)
    n_med = np.zeros((P, L))
    mean = np.zeros((P, L, len(SIGNATURE)))
    std = np.zeros((P, L, len(SIGNATURE)))
    lam = np.zeros((P, L, 3))
    with bar("references", P * L, wanted(progress)) as advance:
        for p, (_, s, a) in enumerate(specs):
            for l, c in enumerate(counts):
                r = sample_signatures(s, c, angle=a, noise=noise, samples=samples, angle_jitter=angle_jitter,
                                      sampling=sampling, seed=[seed, p, l])
                ok = np.isfinite(r["signature"]).all(axis=1)
                if ok.sum() < 2:
                    raise LidarfxError(f"{s} at {c} points: fewer than 2 samples with a signature; raise the count")
                mean[p, l] = r["signature"][ok].mean(axis=0)
                std[p, l] = r["signature"][ok].std(axis=0)
                lam[p, l] = r["lambda_r2"][ok].mean(axis=0)
                n_med[p, l] = float(np.median(r["n"]))
                advance(1)
    # the classifier interpolates in the median count, which must increase from level to level
    if (np.diff(n_med, axis=1) <= 0).any():
        raise LidarfxError(f"count levels {counts} are too close: the samples' median neighbour counts do not increase")
    params = {"counts": list(counts), "noise": noise, "edge_angles": edge_angles, "angle_jitter": float(angle_jitter),
              "samples": samples, "sampling": sampling, "seed": seed, "extent": EXTENT, "radius": 1.0, "lidarfx_version": __version__}
    return References([n for n, _, _ in specs], [s for _, s, _ in specs], [a for _, _, a in specs],
                      np.asarray(counts, np.int64), n_med, mean, std, lam, params)
