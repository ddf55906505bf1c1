"""The scikit-learn side of the classifier: a feature transformer and the estimators.

``LidarFeatures`` turns point clouds into a feature matrix; it is a regular
scikit-learn transformer, so ``Pipeline([("features", LidarFeatures()),
("classifier", HistGradientBoostingClassifier())])`` works, and every
scikit-learn tool (``cross_val_score``, ``permutation_importance``, grid
search, ...) works on the matrix it returns.

What ``transform`` accepts (``X``):

* a :class:`~lidarfx.PointCloud` — one row per point;
* a :class:`CloudSample` ``(cloud, index)`` — rows for the points in ``index``
  only, with every point of ``cloud`` still serving as a neighbour (cheap
  sparse training samples);
* a list of the above — the rows stacked in order;
* a 2-D array with one column per feature — returned unchanged (a matrix
  computed earlier).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numba as nb
import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin

from .. import _parallel as parallel
from ..cloud import PointCloud, measurement_flags
from ..errors import LidarfxError, LidarfxWarning
from ..features.api import check_options, radii_list, scale_suffix
from ..features import slots as S
from ..crs import unit_to_metre

__all__ = [
    "CloudSample",
    "LidarFeatures",
    "DEFAULT_FEATURES",
    "DEFAULT_RADII",
    "EXTRA_INPUTS",
    "CLASSIFIERS",
    "make_classifier",
    "make_pipeline",
    "usable_mask",
    "balanced_sample",
    "feature_list",
    "RETURN_INPUTS",
    "SPACING_DISC_POINTS",
    "return_information",
    "point_spacing",
    "spacing_radii",
    "unit_to_metre",
    "pulse_ids",
    "pulse_heights",
]

#: radii of the default multi-scale run (m), chosen for ALS at 10–100 pts/m² (docs/classification.md)
DEFAULT_RADII: tuple[float, ...] = (1.0, 2.0, 3.0)

#: the default feature list (per radius for neighbourhood features), chosen by spatial-block
#: and leave-one-tile-out cross-validation on the IGN training tiles (docs/classification.md).
#: Orientation (normal_x/y, aspect) and absolute densities (density_2d/3d, n_neighbours) are
#: left out on purpose: they do not transfer between scenes, surveys and point densities.  The
#: Chehata height group (dz_below, dz_above, z_range, z_std) is left out and height above
#: ground is capped (``hag_cap``): absolute heights let a model learn "taller than anything
#: in training = building" (trees of a tile with tall trees became buildings: leave-one-tile-out
#: OA 0.85 with them, 0.94 without).  Slope-dependent ratios are left out (see below).
DEFAULT_FEATURES: tuple[str, ...] = (
    # eigen (Chehata 2009)
    "eigenvalue1", "eigenvalue2", "eigenvalue3", "eigenvalue_sum", "linearity", "planarity",
    "sphericity", "anisotropy", "omnivariance", "eigenentropy", "surface_variation", "verticality",
    # local plane (slope is left out: a monotone function of verticality, trees never need both)
    "plane_distance", "plane_std", "plane_inlier_ratio",
    # slope-adaptive echo ratio (Höfle 2009): 100 % on any plane up to 80°, so sloped ground does
    # not look like vegetation; the plain echo_ratio / neighbour_ratio / density_ratio fall
    # like cos(slope) and are left out
    "echo_ratio_slope",
    # Lang's height-difference histogram (dh_std = z_std is left out)
    "dh_peaks", "dh_peak_distance", "dh_share_above", "dh_share_below", "dh_entropy",
    "dh_skewness", "dh_max_bin",
    # spatial distribution
    "centroid_offset", "octant_occupancy", "z_asymmetry",
    # per point
    "return_ratio", "number_of_returns", "height_above_ground",
)

#: cap of height_above_ground (m), see LidarFeatures
DEFAULT_HAG_CAP = 5.0

#: neighbour clouds are thinned at random so that a disc of the smallest radius holds at most this
#: many points on average (125 ≈ 40 points/m² at r = 1 m; TLS radii of 0.1 m allow 4 000 points/m²)
DEFAULT_MAX_DISC_POINTS = 125.0

#: the return inputs of the default list: left out of the default when a training file records no
#: return numbers (TLS, MLS: no fields, 0 in every point, or every point 1 of 1), see
#: :func:`return_information` and ``lidarfx.classify.model.resolve_defaults``
RETURN_INPUTS: tuple[str, ...] = ("return_ratio", "number_of_returns")

#: default radii from the point spacing: the smallest radius is that of a disc holding this many
#: points on a surface sampled at the training files' spacing (the thinning's 125: at the ALS design
#: density of 40 pts/m² that is the 1 m of :data:`DEFAULT_RADII`)
SPACING_DISC_POINTS = 125.0


def return_information(cloud: PointCloud) -> str:
    """What the cloud's return numbers say (usable points, :func:`usable_mask`): ``"none"`` (a field
    missing, or 0 in every point: AHN4 exports, LAS files written from TLS / MLS scans; the return
    inputs cannot be computed), ``"single"`` (every point 1 of 1: the return inputs would be
    constant) or ``"multi"``."""
    if not all(_has_field(cloud, f) for f in ("return_number", "number_of_returns")):
        return "none"
    ok = usable_mask(cloud)
    rn = np.asarray(cloud["return_number"])[ok]
    nr = np.asarray(cloud["number_of_returns"])[ok]
    return "single" if np.all(rn == 1) and np.all(nr == 1) else "multi"


def point_spacing(xyz: np.ndarray, *, sample: int = 10_000, seed: int = 0) -> float:
    """Mean point spacing (m) on the surfaces of a cloud: ``1 / √ρ`` with ρ the points per m² of a
    surface, from the median distance d₂₀ to the 20th nearest neighbour over a seeded sample of at
    most ``sample`` points (on a plane d₂₀ = √(20 / (π ρ))).  3-D, so vertical surfaces (facades,
    poles) count as they are scanned; coordinates in metres."""
    from ..neighbors import NeighborIndex, default_cell_for_knn

    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) < 21:
        raise LidarfxError("fewer than 21 points: cannot measure the point spacing; give the radii (-r)")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(xyz), size=min(sample, len(xyz)), replace=False)
    index = NeighborIndex(xyz, default_cell_for_knn(xyz - xyz.min(axis=0), 21))
    _, d = index.knn(xyz[pick], 21)  # the point itself and 20 neighbours
    d20 = d[:, -1]
    d20 = d20[np.isfinite(d20) & (d20 > 0)]
    if not len(d20):
        raise LidarfxError("cannot measure the point spacing: the points coincide; give the radii (-r)")
    return float(np.median(d20)) * math.sqrt(math.pi / 20.0)


def spacing_radii(spacing: float) -> list[float]:
    """The default radii for a point spacing (m): :data:`DEFAULT_RADII` (1, 2, 3 m) unless a disc of
    1 m holds more than :data:`SPACING_DISC_POINTS` points at that spacing (spacing below 0.16 m,
    denser than about 40 pts/m² on a surface: dense ALS, MLS, TLS); then r, 2r, 3r with r the radius of a
    disc holding that many points, to the centimetre (at least 1 cm).  Never larger than the ALS
    radii: those were validated on the IGN tiles, larger ones for sparse clouds were not."""
    r = math.sqrt(SPACING_DISC_POINTS / math.pi) * float(spacing)
    if not r < DEFAULT_RADII[0]:
        return list(DEFAULT_RADII)
    r1 = max(0.01, round(r, 2))
    return [round(f * r1, 2) for f in (1, 2, 3)]

#: per-point inputs that are not neighbourhood features (no radius suffix)
EXTRA_INPUTS: dict[str, str] = {
    "height_above_ground": "z minus the ground surface (TIN) under the point, capped at hag_cap (default 5 m); "
    "ground from the SMRF filter (label-free) or, with ground='class', from the cloud's class 2",
    "number_of_returns": "number of returns of the pulse (LAS field)",
    "return_number": "return number (LAS field)",
    "intensity": "raw intensity (LAS field)",
    "intensity_norm": "intensity divided by the cloud's median intensity",
    "z": "z minus the cloud's lowest z",
    "pulse_above": "height of the point's pulse's first return above the point (m, within ±hag_cap; 0 for "
    "a first return); pulses from file order, GPS time and return numbers (see pulse_ids)",
    "pulse_below": "height of the point above its pulse's last return (m, within ±hag_cap; 0 for a last "
    "return)",
}

#: LAS fields each extra input needs
_NEEDS = {
    "number_of_returns": ("number_of_returns",),
    "return_number": ("return_number",),
    "return_ratio": ("return_number", "number_of_returns"),
    "intensity": ("intensity",),
    "intensity_norm": ("intensity",),
    "pulse_above": ("gps_time", "return_number", "number_of_returns"),
    "pulse_below": ("gps_time", "return_number", "number_of_returns"),
}

CLASSIFIERS: dict[str, str] = {
    "hgb": "HistGradientBoostingClassifier (gradient-boosted trees; handles NaN)",
    "rf": "RandomForestClassifier (Breiman; handles NaN)",
    "nb": "GaussianNB (Gaussian naive Bayes; NaN replaced by the training median)",
}


# --------------------------------------------------------------------------- inputs
@dataclass
class CloudSample:
    """Points ``index`` of ``cloud`` (all points when ``index`` is None); every
    point of ``cloud`` serves as a neighbour."""

    cloud: PointCloud
    index: np.ndarray | None = None
    ids: np.ndarray | None = None
    """Identity of each row for the per-point random draws of MSAC (default: ``index``); a
    chunk of a larger cloud gives the whole cloud's (:mod:`lidarfx.tiles`)."""

    def __post_init__(self) -> None:
        if not isinstance(self.cloud, PointCloud):
            raise LidarfxError("CloudSample needs a PointCloud")
        if self.index is not None:
            idx = np.asarray(self.index)
            if idx.dtype == bool:
                if idx.shape != (len(self.cloud),):
                    raise LidarfxError(f"sample mask must have length {len(self.cloud)}")
                idx = np.flatnonzero(idx)
            idx = idx.astype(np.int64, copy=False).ravel()
            if idx.size and (idx.min() < 0 or idx.max() >= len(self.cloud)):
                raise LidarfxError("sample indices out of range")
            self.index = idx

    def __len__(self) -> int:
        return len(self.cloud) if self.index is None else int(len(self.index))

    @property
    def name(self) -> str:
        return str(self.cloud.meta.get("name") or self.cloud.meta.get("source") or "the cloud")


def usable_mask(cloud: PointCloud) -> np.ndarray:
    """Points that are real measurements: not withheld, not synthetic, and — when
    the cloud carries return numbers — ``return_number > 0``.

    IGN LiDAR HD *virtual* points (class 66) have return number 0; they are
    excluded from neighbourhoods and from prediction without looking at the
    (reference) classification.
    """
    ok, returned = measurement_flags(cloud.xyz, cloud.attrs)
    if returned is not None and returned.any():
        ok &= returned
    return ok


def _has_field(cloud: PointCloud, name: str) -> bool:
    if name not in cloud:
        return False
    v = np.asarray(cloud[name])
    return bool(v.size) and bool(np.any(v != 0))


def feature_list(features: str | Iterable[str] | None, radii: Sequence[float] | None,
                 neighbourhood: str = "sphere", k: int | None = None) -> tuple[list[str], tuple, list[str], list[float]]:
    """Expand groups / names into ``(names_out, slots, point_names, radii)``.

    Neighbourhood features get a scale suffix for every radius, always (also
    for a single radius), so a model can tell ``planarity_r1.00`` from
    ``planarity_r0.50``.
    """
    from ..features import slots as S
    from ..features.registry import resolve

    tokens = DEFAULT_FEATURES if features is None else features
    if isinstance(tokens, str):
        tokens = tokens.split(",")
    tokens = [t.strip() for t in tokens if t and t.strip()]
    if not tokens:
        raise LidarfxError("no features requested")
    # "default" = the default list; "-name" takes a group, a feature or a per-point input out of what
    # came before it (the registry handles groups and features, the per-point inputs are handled here)
    tokens = [x for t in tokens for x in (DEFAULT_FEATURES if t.lower() == "default" else (t,))]
    extras: list[str] = []
    rest: list[str] = []
    hag_names = ("ground", "height_above_ground")  # the registry's group "ground" is this one input
    for t in tokens:
        neg = t.startswith("-")
        bare = t[1:].strip().lower() if neg else t.lower()
        if neg and bare in hag_names and "height_above_ground" in extras:
            extras.remove("height_above_ground")
        elif bare not in EXTRA_INPUTS or (neg and bare in hag_names):
            rest.append(t)  # groups and features, and the height above ground asked for as group "ground"
        elif not neg:
            if bare not in extras:
                extras.append(bare)
        elif bare in extras:
            extras.remove(bare)
        else:
            raise LidarfxError(f"cannot leave out {bare!r}: it is not among the features requested before it")
    slots: tuple = ()
    point: list[str] = []
    rs = radii_list(None, radii)
    if rest:
        req = resolve(rest, allow_empty=True)
        slots, point = req.slots, list(req.point)
        if slots or point:
            check_options(req, rs, neighbourhood, k)  # the feature engine's own checks
    if not slots and not point and not extras:
        left = any(t.startswith("-") for t in tokens)
        raise LidarfxError("no features requested" + (" (all were left out)" if left else ""))
    if len({scale_suffix(r) for r in rs}) != len(rs):
        raise LidarfxError(f"radii must differ in the second decimal: {rs}")
    names: list[str] = []
    if slots:
        suffixes = [f"_k{int(k)}"] if neighbourhood == "knn" else [scale_suffix(r) for r in rs]
        for sfx in suffixes:
            names += [S.NAMES[s] + sfx for s in slots]
    names += point + [e for e in extras if e not in point]
    return names, tuple(slots), point, rs


# --------------------------------------------------------------------------- transformer
class LidarFeatures(TransformerMixin, BaseEstimator):
    """Per-point features of point clouds as a matrix (a scikit-learn transformer).

    Parameters
    ----------
    features:
        Feature groups or names (as for :func:`lidarfx.compute_features`) plus
        the per-point inputs of :data:`EXTRA_INPUTS` (``height_above_ground``,
        ``number_of_returns``, ``intensity``, ...).  Default
        :data:`DEFAULT_FEATURES`.
    radii:
        Neighbourhood radii (m); every neighbourhood feature is computed at
        every radius and named with the suffix ``_r1.00``.
    neighbourhood, k, scanner, hist_bins:
        Passed to the feature engine (``scanner`` orients TLS normals).
    max_disc_points:
        Neighbourhood density limit, as the mean number of points in a disc of
        the smallest radius: density limit = max_disc_points / (π r_min²)
        points per m² (density measured over occupied 2 m × 2 m cells, all
        returns).  A denser cloud serves as neighbour cloud only through a
        seeded random subset of that density; features are still computed for
        every point.  Features then see about the point density the model was
        trained on, and an 84 pts/m² cloud costs what a 40 pts/m² one does.
        Default 125 (≈ 40 pts/m² at r = 1 m).  None = never thin.
    hag_cap:
        Upper limit of ``height_above_ground`` (m; None = no limit).  Default
        5 m: enough to tell ground and low objects from the rest, without
        letting the classifier key on absolute heights it cannot extrapolate.
    ground:
        Ground for ``height_above_ground``: ``"smrf"`` (default: the SMRF
        filter of :mod:`lidarfx.ground`, which never looks at the
        classification) or ``"class"`` (the cloud's class 2 points — only for
        clouds whose ground is already classified; in an evaluation on labelled
        data it leaks the reference), or ``"attribute"`` (the cloud's own
        ``height_above_ground`` attribute, e.g. from ``lidarfx ground --hag``:
        what a chunked prediction needs, :mod:`lidarfx.tiles`).
    precomputed:
        Read the neighbourhood features from the cloud's attributes (e.g. a
        file written by ``lidarfx features -r 1 -r 2 -r 4``) instead of
        computing them; a missing one is an error.
    progress:
        Progress bars of the feature engine.
    """

    def __init__(
        self,
        features: Sequence[str] | str | None = None,
        radii: Sequence[float] = DEFAULT_RADII,
        neighbourhood: str = "sphere",
        k: int | None = None,
        scanner: Sequence[float] | None = None,
        hist_bins: int = 10,
        ground: str = "smrf",
        hag_cap: float | None = DEFAULT_HAG_CAP,
        max_disc_points: float | None = DEFAULT_MAX_DISC_POINTS,
        precomputed: bool = False,
        progress: bool | None = False,
    ) -> None:
        self.features = features
        self.radii = radii
        self.neighbourhood = neighbourhood
        self.k = k
        self.scanner = scanner
        self.hist_bins = hist_bins
        self.ground = ground
        self.hag_cap = hag_cap
        self.max_disc_points = max_disc_points
        self.precomputed = precomputed
        self.progress = progress

    # ------------------------------------------------------------------ sklearn API
    def feature_plan(self):
        if self.ground not in ("smrf", "class", "attribute"):
            raise LidarfxError(f"ground must be 'smrf', 'class' or 'attribute', got {self.ground!r}")
        if self.hag_cap is not None and not (self.hag_cap > 0):
            raise LidarfxError(f"hag_cap must be a positive height in m or None, got {self.hag_cap!r}")
        if self.max_disc_points is not None and not (self.max_disc_points > 0):
            raise LidarfxError(f"max_disc_points must be a positive number or None, got {self.max_disc_points!r}")
        names, slots, point, rs = feature_list(self.features, self.radii, self.neighbourhood, self.k)
        return names, slots, point, rs

    def fit(self, X: Any = None, y: Any = None) -> "LidarFeatures":
        names, *_ = self.feature_plan()
        self.feature_names_out_ = np.asarray(names, dtype=object)
        self.n_features_out_ = len(names)
        return self

    def get_feature_names_out(self, input_features: Any = None) -> np.ndarray:
        if not hasattr(self, "feature_names_out_"):
            self.fit()
        return self.feature_names_out_.copy()

    def transform(self, X: Any) -> np.ndarray:
        if not hasattr(self, "feature_names_out_"):
            self.fit()
        names, slots, point, rs = self.feature_plan()
        if isinstance(X, np.ndarray) and X.ndim == 2:
            if X.shape[1] != len(names):
                raise LidarfxError(f"feature matrix has {X.shape[1]} columns, the transformer makes {len(names)}")
            return X
        samples = _as_samples(X)
        if not samples:
            return np.empty((0, len(names)), np.float32)
        cache: dict[int, Any] = {}
        blocks = [self.feature_matrix(s, names, slots, point, rs, cache) for s in samples]
        return np.vstack(blocks) if len(blocks) > 1 else blocks[0]

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.requires_fit = False
        return tags

    # ------------------------------------------------------------------ internals
    def _hint(self, lacking: list[str]) -> str:
        """", e.g. --features …": this transformer's own list without the ``lacking`` inputs."""
        spec = self.features
        tokens = ["default"] if spec is None else [str(t).strip() for t in (spec.split(",") if isinstance(spec, str)
                                                                            else spec)]
        tokens = [t for t in tokens if t]
        asked = {t.lower() for t in tokens}
        kept = [t for t in tokens if t.lower() not in lacking]
        if not [t for t in kept if not t.startswith("-")]:
            return ""
        return f", e.g. --features {','.join(kept + ['-' + n for n in lacking if n not in asked])}"

    def check_cloud(self, cloud: PointCloud, name: str = "the cloud") -> None:
        """Refuse a cloud that lacks a field the features need (clear one-line error)."""
        names, *_ = self.feature_plan()
        for feat in names:
            for field in _NEEDS.get(feat, ()):
                if not _has_field(cloud, field):
                    what = {"intensity": "no intensity", "gps_time": "no GPS time"}.get(field, "no return information")
                    how = f"has no {field!r} field" if field not in cloud else f"has {field!r} = 0 for every point"
                    lacking = [n for n in names if any(not _has_field(cloud, f) for f in _NEEDS.get(n, ()))]
                    raise LidarfxError(f"the features include {feat!r} but {name} {how} ({what}); "
                                       f"use a model trained without {', '.join(lacking)}{self._hint(lacking)}")
        if self.precomputed:
            unit = unit_to_metre(cloud)
            if unit != 1.0:
                raise LidarfxError(
                    f"{name} is in a unit of {unit:g} m (CRS), but precomputed features are in coordinate "
                    "units while the model's are in metres; predict without --precomputed"
                )
            need = [n for n in names if n not in EXTRA_INPUTS and n not in _NEEDS]
            missing = [n for n in need if n not in cloud]
            if missing:
                rs = ", ".join(f"{r:g}" for r in sorted(set(float(r) for r in self.radii)))
                have = sorted(n for n in cloud.names if "_r" in n or "_k" in n)[:6]
                raise LidarfxError(
                    f"{name} lacks {len(missing)} of the {len(need)} precomputed features the model needs "
                    f"(e.g. {', '.join(missing[:4])}); the model was trained at radii {rs} m"
                    + (f", the cloud has {', '.join(have)}" if have else "")
                    + f" — compute them with: {self.features_command()} (or predict without --precomputed)"
                )
            bad = int(np.count_nonzero(~usable_mask(cloud))) if len(cloud) else 0
            if bad:  # a plain predict drops them before the features (ClassifierModel.predict)
                warnings.warn(
                    f"{name}: {bad:,} virtual, withheld or synthetic points are in no neighbourhood of a plain "
                    "predict, but features written by lidarfx features have them as neighbours, so the precomputed "
                    "features are not the ones a plain predict computes and some points may get another class",
                    LidarfxWarning, stacklevel=3)

    def thinning_limit(self, rs: Sequence[float] | None = None) -> tuple[float | None, int]:
        """``(limit, min_keep)``: the density (points per m²) above which the neighbour cloud is
        thinned (``max_disc_points`` per disc of the smallest radius ``rs[0]``; None: never) and
        the fewest points a thinned neighbour cloud keeps (:func:`thinning_mask`)."""
        if rs is None:
            rs = self.feature_plan()[3]
        limit = None
        if self.max_disc_points is not None and rs:
            limit = float(self.max_disc_points) / (math.pi * rs[0] * rs[0])  # float: no OverflowError
        # 0 for absurd radii: no thinning; never fewer points than one disc should hold
        return (limit if limit else None), int(min(self.max_disc_points or 0, 1e9))

    def _warn_unthinned(self, cloud: PointCloud, rs: Sequence[float], name: str) -> None:
        """With ``precomputed``: warn when a plain prediction would thin ``cloud``'s neighbours
        (``lidarfx features`` never thins, so the file's features are not the model's)."""
        limit, min_keep = self.thinning_limit(rs)
        if limit is None or not len(cloud):
            return
        xyz = cloud.xyz * unit_to_metre(cloud)
        if thinning_mask(xyz, limit, min_keep=min_keep) is None:
            return
        warnings.warn(
            f"{name}: {point_density(xyz):.1f} points/m² is denser than the {limit:.1f} points/m² to which the "
            f"model thins its neighbour clouds ({self.max_disc_points:g} points per disc of {rs[0]:g} m); "
            "features written by lidarfx features have every point as a neighbour, so the precomputed features "
            "are not the ones a plain predict computes and some points get another class (docs/classification.md "
            "§4); predict without --precomputed for the model's own features",
            LidarfxWarning, stacklevel=4)

    def features_command(self) -> str:
        """The ``lidarfx features`` command that writes every neighbourhood feature this transformer
        reads (whole groups: a superset), for ``--precomputed``."""
        _, slots, _, rs = self.feature_plan()
        groups = [g for g, members in S.GROUPS.items() if set(members) & set(slots)]
        args = ["lidarfx features IN OUT"]
        if self.neighbourhood != "sphere":
            args.append(f"-n {self.neighbourhood}")
        if self.neighbourhood == "knn":
            args.append(f"-k {self.k}")
        args += [f"-r {r:g}" for r in sorted(set(float(r) for r in rs))]
        if self.scanner is not None:
            args.append("--scanner " + ",".join(f"{v:g}" for v in self.scanner))
        if int(self.hist_bins) != 10:
            args.append(f"--bins {int(self.hist_bins)}")
        args.append("--features " + ",".join(groups))
        cmd = " ".join(args)
        if self.neighbourhood == "knn" or len(set(rs)) == 1:  # lidarfx features adds no suffix then
            sfx = f"_k{int(self.k)}" if self.neighbourhood == "knn" else scale_suffix(rs[0])
            cmd += f" and add the suffix {sfx} to their names"
        return cmd

    def _hag(self, cloud: PointCloud, unit: float, cache: dict) -> np.ndarray:
        """The height above ground of every point of ``cloud`` in metres, computed once per cloud."""
        key = id(cloud)
        if key not in cache:
            cache[key] = hag(cloud, self.ground) * np.float32(unit)
        return cache[key]

    def feature_matrix(self, sample: "CloudSample", names, slots, point, rs, cache) -> np.ndarray:
        from ..features.api import feature_arrays, feature_index
        from ..features.registry import Request

        cloud, idx = sample.cloud, sample.index
        self.check_cloud(cloud, sample.name)
        # every length is computed in metres: radii, densities, HAG and the cap are metres, so
        # a model trained on metre data works on a US-feet cloud and vice versa
        unit = unit_to_metre(cloud)
        m = len(sample)
        out = np.empty((len(names), m), dtype=np.float32)  # one row per feature: contiguous writes
        col = {n: i for i, n in enumerate(names)}
        if "height_above_ground" in col and not (self.precomputed and "height_above_ground" in cloud):
            self._hag(cloud, unit, cache)  # first: its triangulation is the peak, before the index exists
        if slots and m:
            if self.precomputed:
                key = ("unthinned", id(cloud))
                if key not in cache and sample.ids is None:  # once per cloud; a chunk of a larger one
                    cache[key] = True  # (lidarfx.tiles, ids given) does not know the whole cloud's density
                    self._warn_unthinned(cloud, rs, sample.name)
                for n in names:
                    if n in EXTRA_INPUTS or n in _NEEDS:
                        continue
                    v = np.asarray(cloud[n], dtype=np.float32)
                    out[col[n]] = v if idx is None else v[idx]
            else:
                key = ("metres", id(cloud))
                if key not in cache:  # once per cloud, not per chunk of queries
                    cache[key] = cloud.xyz if unit == 1.0 else cloud.xyz * unit
                xyz = cache[key]
                key = ("thin", id(cloud))
                if key not in cache:
                    limit, min_keep = self.thinning_limit(rs)
                    cache[key] = thinning_mask(xyz, limit, min_keep=min_keep)
                keep = cache[key]
                req = Request(tuple(slots), ())
                held = cache.get("index")
                if held is None or held[0] != id(cloud):  # the neighbour cloud and its index, shared by all
                    # chunks of this cloud; only the current cloud's is kept (a list of clouds comes cloud by cloud)
                    cache.pop("index", None)
                    nb_xyz = xyz if keep is None else xyz[keep]
                    cache["index"] = (id(cloud), nb_xyz, feature_index(nb_xyz, self.neighbourhood, self.k, rs, req))
                _, nb_xyz, index = cache["index"]
                if keep is None:
                    q_xyz = None if idx is None else xyz[idx]
                else:
                    q_xyz = xyz if idx is None else xyz[idx]
                arrays = feature_arrays(
                    nb_xyz,
                    req,
                    index=index,
                    radii=rs or None,
                    neighbourhood=self.neighbourhood,
                    k=self.k,
                    query_xyz=q_xyz,
                    query_ids=idx if sample.ids is None else sample.ids,
                    scanner=None if self.scanner is None else np.asarray(self.scanner, dtype=np.float64) * unit,
                    hist_bins=int(self.hist_bins),
                    progress=self.progress,
                )
                from ..features import slots as S

                sfx_of = ([f"_k{int(self.k)}"] if self.neighbourhood == "knn" else [scale_suffix(r) for r in rs])
                single = len(sfx_of) == 1
                for si, sfx in enumerate(sfx_of):
                    for s in slots:
                        key = S.NAMES[s] + ("" if single else sfx)
                        out[col[S.NAMES[s] + sfx]] = arrays[key]
        def sel(a, dtype=np.float32) -> np.ndarray:  # this chunk's rows (select first: a chunk, not the cloud)
            return np.asarray(a if idx is None else np.asarray(a)[idx], dtype=dtype)

        for n in point:
            if n == "return_ratio":
                rn = sel(cloud["return_number"])
                nr = sel(cloud["number_of_returns"])
                with np.errstate(divide="ignore", invalid="ignore"):
                    out[col[n]] = np.where(nr > 0, rn / nr, np.nan)
            else:  # pragma: no cover - the registry has no other per-point feature
                raise LidarfxError(f"unknown per-point feature {n!r}")
        for n in names:
            if n not in EXTRA_INPUTS:
                continue
            if n == "height_above_ground":
                if self.precomputed and "height_above_ground" in cloud:
                    v = sel(cloud["height_above_ground"])
                else:
                    v = sel(self._hag(cloud, unit, cache))
                if self.hag_cap is not None:
                    v = np.minimum(v, _cap32(self.hag_cap))
            elif n in ("number_of_returns", "return_number", "intensity"):
                v = sel(cloud[n])
            elif n == "intensity_norm":
                key = ("int", id(cloud))
                if key not in cache:
                    it = np.asarray(cloud["intensity"], dtype=np.float32)
                    med = float(np.median(it[it > 0])) if np.any(it > 0) else 1.0
                    cache[key] = it / med
                v = sel(cache[key])
            elif n in ("pulse_above", "pulse_below"):
                key = ("pulse", id(cloud))
                if key not in cache:
                    pid = pulse_ids(cloud)
                    _warn_broken_pulses(cloud, pid, sample.name)
                    cache[key] = pulse_heights(cloud, pid)
                v = sel(cache[key][0 if n == "pulse_above" else 1]) * np.float32(unit)
                lim = _cap32(self.hag_cap)
                v = np.clip(v, -lim, lim)
            elif n == "z":
                key = ("zmin", id(cloud))
                if key not in cache:
                    cache[key] = cloud.z.min() if len(cloud) else 0.0
                v = ((sel(cloud.z, np.float64) - cache[key]) * unit).astype(np.float32)
            else:  # pragma: no cover
                raise LidarfxError(f"unknown input {n!r}")
            out[col[n]] = v
        return _rows(out)


@nb.njit(cache=True, nogil=True)
def _transpose_blocks(lo, hi, cols: np.ndarray, out: np.ndarray) -> None:
    k = cols.shape[0]
    for b in range(lo, hi):  # 1024 rows at a time: the block stays in cache
        for j in range(k):
            for i in range(b * 1024, min(b * 1024 + 1024, cols.shape[1])):
                out[i, j] = cols[j, i]


def _rows(cols: np.ndarray) -> np.ndarray:
    """The (m, k) C-order matrix of a (k, m) one.  The features arrive one at a time, and writing
    each into a column of a row-major matrix is a strided scatter (2 s per million rows of 81
    columns here, against 0.1 s for contiguous rows plus this blocked transpose)."""
    out = np.empty((cols.shape[1], cols.shape[0]), dtype=cols.dtype)
    if out.size:
        parallel.run(_transpose_blocks, (cols.shape[1] + 1023) // 1024, cols, out, grain=16)
    return out


def point_density(xyz: np.ndarray, cell: float = 2.0) -> float:
    """Points per m² over the occupied ``cell`` × ``cell`` squares (all returns)."""
    if len(xyz) == 0:
        return 0.0
    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    top = int(key.max()) + 1
    # occupied cells: a count per cell when the grid is not much larger than the cloud (no sort)
    if top <= 4 * len(key) + 1_000_000:
        occupied = np.count_nonzero(np.bincount(key, minlength=top))
    else:
        occupied = len(np.unique(key))
    return float(len(xyz)) / (occupied * cell * cell)


def _cap32(cap: float | None) -> np.float32:
    """A height cap as float32; None, and caps beyond float32's range, are +inf (no overflow warning)."""
    if cap is None or not float(cap) < float(np.finfo(np.float32).max):
        return np.float32(np.inf)
    return np.float32(cap)


def thinning_mask(xyz: np.ndarray, max_density: float | None, seed: int = 0, min_keep: int = 0) -> np.ndarray | None:
    """Random subset (bool mask) bringing the density down to ``max_density``; None if not needed.
    It keeps about ``min_keep`` points at least (a disc far wider than the cloud asked for a
    density that left no point: ``-r 1e9`` said "the point cloud is empty")."""
    if max_density is None:
        return None
    d = point_density(xyz)
    if d <= max_density:
        return None
    frac = max(max_density / d, min(1.0, min_keep / max(len(xyz), 1)))
    if frac >= 1.0:
        return None
    return np.random.default_rng(seed).random(len(xyz)) < frac


def pulse_ids(cloud: PointCloud) -> np.ndarray | None:
    """A pulse number for every point (int64), or None without GPS times and return numbers.

    LAS has no pulse id.  The returns of one pulse share ``gps_time`` and
    ``number_of_returns`` and follow each other in the file with rising
    ``return_number``: such a run is one pulse.  GPS time alone is not a key:
    stored with too few digits, several pulses share one time (IGN tile 77050:
    25 453 times for 73 355 points; the runs make 99.1 % of its points complete
    pulses).  Where a run is incomplete (fewer points than ``number_of_returns``,
    e.g. returns written out of order) but all points with its time and
    ``number_of_returns`` make exactly one pulse, that group is used instead.
    Pulses cut by a tile edge stay incomplete; their present returns form the pulse.
    """
    need = ("gps_time", "return_number", "number_of_returns")
    if not len(cloud) or not all(_has_field(cloud, f) for f in need):
        return None
    t = np.asarray(cloud["gps_time"], dtype=np.float64)
    rn = np.asarray(cloud["return_number"]).astype(np.int64)
    nr = np.asarray(cloud["number_of_returns"]).astype(np.int64)
    new = np.ones(len(t), dtype=bool)
    new[1:] = (t[1:] != t[:-1]) | (nr[1:] != nr[:-1]) | (rn[1:] <= rn[:-1])
    run = np.cumsum(new) - 1
    run_complete = np.bincount(run)[run] == nr
    order = np.lexsort((nr, t))
    ts, ns = t[order], nr[order]
    key_new = np.ones(len(t), dtype=bool)
    key_new[1:] = (ts[1:] != ts[:-1]) | (ns[1:] != ns[:-1])
    group = np.empty(len(t), dtype=np.int64)
    group[order] = np.cumsum(key_new) - 1
    group_complete = np.bincount(group)[group] == nr
    use_group = ~run_complete & group_complete
    return np.where(use_group, group + int(run[-1]) + 1, run)


def _warn_broken_pulses(cloud: PointCloud, pid: np.ndarray | None, name: str) -> None:
    """Warn when fewer than 80 % of the multi-return points lie in complete pulses (file not in
    acquisition order, e.g. spatially sorted): the pulse inputs would be wrong without a word."""
    if pid is None:
        return
    nr = np.asarray(cloud["number_of_returns"])
    multi = nr > 1
    whole = np.bincount(pid)[pid] == nr  # the pulse has all its returns
    if multi.sum() >= 100 and whole[multi].mean() < 0.8:
        warnings.warn(f"{name}: only {whole[multi].mean():.0%} of the multi-return points form complete pulses "
                      "(returns not in acquisition order, e.g. a spatially sorted file?); pulse_above / "
                      "pulse_below are unreliable", LidarfxWarning, stacklevel=5)


def pulse_heights(cloud: PointCloud, pid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(above, below)`` per point (float32, coordinate units): the z of the point's pulse's
    first present return minus the point's z, and the point's z minus its pulse's last present
    return's; pulses ``pid`` (default :func:`pulse_ids`); NaN without pulse information."""
    if pid is None:
        pid = pulse_ids(cloud)
    if pid is None:
        nan = np.full(len(cloud), np.nan, dtype=np.float32)
        return nan, nan.copy()
    z = cloud.z
    rn = np.asarray(cloud["return_number"]).astype(np.int64)
    order = np.lexsort((rn, pid))  # by pulse, then by return number
    ps = pid[order]
    first = np.ones(len(ps), dtype=bool)
    first[1:] = ps[1:] != ps[:-1]
    last = np.ones(len(ps), dtype=bool)
    last[:-1] = ps[1:] != ps[:-1]
    start = np.flatnonzero(first)
    stop = np.flatnonzero(last)
    size = np.diff(np.append(start, len(ps)))
    zs = z[order]
    above = np.empty(len(z), dtype=np.float32)
    below = np.empty(len(z), dtype=np.float32)
    above[order] = np.repeat(zs[start], size) - zs
    below[order] = zs - np.repeat(zs[stop], size)
    return above, below


def pulse_thinning_mask(cloud: PointCloud, fraction: float, seed: int = 0) -> np.ndarray:
    """Keep each laser pulse with probability ``fraction`` (bool mask over the points).

    A pulse is given by :func:`pulse_ids` (all its returns are kept or dropped
    together, as in a survey flown with fewer pulses), or by ``gps_time`` alone
    when the cloud has no return numbers.  Without GPS times, or when they cannot
    be pulse stamps (fewer pulses than one per 15 points, the most returns a LAS
    pulse can have — e.g. all zero), every point is its own pulse.
    """
    rng = np.random.default_rng(seed)
    pulse = pulse_ids(cloud)
    if pulse is None and "gps_time" in cloud and len(cloud):
        pulse = np.unique(np.asarray(cloud["gps_time"]), return_inverse=True)[1].ravel()
    if pulse is not None:
        n_pulses = int(pulse.max()) + 1
        if n_pulses * 15 >= len(cloud):
            return (rng.random(n_pulses) < fraction)[pulse]
    return rng.random(len(cloud)) < fraction


def terrain_shear(cloud: PointCloud, seed: int = 0) -> PointCloud:
    """A copy with z + f(x, y), f a smooth random terrain (training augmentation).

    f = A·sin(2πx/Lx + φ) + B·sin(2πy/Ly + ψ), A, B ∈ [4, 10] m, Lx, Ly ∈
    [60, 120] m, phases random (seeded): each sine up to about 46°, both together up
    to about 56°.  A vertical shift that depends only on (x, y) keeps walls and trunks
    vertical and leaves the true height above the terrain unchanged, so labels stay
    valid while the ground (and roofs) get slopes the training tiles may not have.
    (The height-above-ground *feature* is recomputed on the copy, by SMRF by default,
    and errs there as it would on real slopes.)
    """
    rng = np.random.default_rng(seed)
    u = unit_to_metre(cloud)
    a, b = rng.uniform(4.0, 10.0, 2) / u
    lx, ly = rng.uniform(60.0, 120.0, 2) / u
    px, py = rng.uniform(0.0, 2 * np.pi, 2)
    xyz = cloud.xyz.copy()
    loc = xyz[:, :2] - xyz[:, :2].min(axis=0) if len(xyz) else xyz[:, :2]
    xyz[:, 2] += a * np.sin(2 * np.pi * loc[:, 0] / lx + px) + b * np.sin(2 * np.pi * loc[:, 1] / ly + py)
    out = PointCloud(xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    out.meta = {**cloud.meta, "name": f"{cloud.meta.get('name', 'cloud')} (terrain-sheared)"}
    return out


def hag(cloud: PointCloud, ground: str = "smrf") -> np.ndarray:
    """Height above ground of every point (float32); ground from SMRF or class 2, or the
    cloud's ``height_above_ground`` attribute (``ground="attribute"``)."""
    try:
        from ..ground import classify_ground, height_above_ground
    except ImportError as exc:  # pragma: no cover - the ground module ships with lidarfx
        raise LidarfxError(f"height_above_ground needs lidarfx.ground ({exc})") from None
    if ground == "attribute":  # written before, e.g. by lidarfx ground --hag (also in chunks)
        if "height_above_ground" not in cloud:
            raise LidarfxError("ground='attribute' needs a height_above_ground attribute (lidarfx ground IN OUT --hag)")
        return np.asarray(cloud["height_above_ground"], dtype=np.float32)
    if ground == "class":
        if "classification" not in cloud:
            raise LidarfxError("ground='class' needs a classification with class 2")
        mask = np.asarray(cloud["classification"]) == 2
    else:
        # ignore_classes=None: the filter must not look at the (reference) classes
        mask = classify_ground(cloud, ignore_classes=None, progress=False)
    if not mask.any():
        raise LidarfxError("no ground found: height_above_ground is not computable for this cloud")
    return np.asarray(height_above_ground(cloud, ground=mask), dtype=np.float32)


def _as_samples(X: Any) -> list[CloudSample]:
    if isinstance(X, PointCloud):
        return [CloudSample(X)]
    if isinstance(X, CloudSample):
        return [X]
    if isinstance(X, (list, tuple)):
        out: list[CloudSample] = []
        for item in X:
            out += _as_samples(item)
        return out
    raise LidarfxError(
        f"LidarFeatures.transform expects a PointCloud, a CloudSample, a list of them or a feature matrix, "
        f"got {type(X).__name__}"
    )


# --------------------------------------------------------------------------- estimators
def make_classifier(kind: str = "hgb", *, n_estimators: int | None = None, random_state: int = 0,
                    n_jobs: int | None = None):
    """A fresh scikit-learn classifier of the given kind (:data:`CLASSIFIERS`).

    ``hgb``: 300 boosting iterations at most (early stopping on 10 % of the
    training sample), learning rate 0.1, 31 leaves.  ``rf``: 100 trees,
    ``max_features="sqrt"``.  ``nb``: Gaussian naive Bayes.  Class balance is
    applied by sample weights at fit time (see :func:`lidarfx.classify.train`).
    """
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.naive_bayes import GaussianNB

    kind = str(kind).lower()
    if kind == "hgb":
        return HistGradientBoostingClassifier(max_iter=int(n_estimators or 300), learning_rate=0.1,
                                              max_leaf_nodes=31, random_state=random_state)
    if kind == "rf":
        return RandomForestClassifier(n_estimators=int(n_estimators or 100), n_jobs=n_jobs if n_jobs else -1,
                                      random_state=random_state)
    if kind == "nb":
        return GaussianNB()
    raise LidarfxError(f"classifier must be one of {', '.join(CLASSIFIERS)}, got {kind!r}")


def make_imputer(kind: str):
    """NaN handling step: median imputation for naive Bayes, pass-through otherwise."""
    if str(kind).lower() == "nb":
        from sklearn.impute import SimpleImputer

        return SimpleImputer(strategy="median", keep_empty_features=True)
    return "passthrough"


def make_pipeline(features=None, radii=DEFAULT_RADII, classifier: str = "hgb", *, n_estimators: int | None = None,
                  random_state: int = 0, n_jobs: int | None = None, **feature_params):
    """``Pipeline([("features", LidarFeatures), ("impute", ...), ("classifier", ...)])``."""
    from sklearn.pipeline import Pipeline

    return Pipeline([
        ("features", LidarFeatures(features=features, radii=radii, **feature_params)),
        ("impute", make_imputer(classifier)),
        ("classifier", make_classifier(classifier, n_estimators=n_estimators, random_state=random_state,
                                       n_jobs=n_jobs)),
    ])


# --------------------------------------------------------------------------- sampling
def balanced_sample(y: np.ndarray, max_per_class: int | None, seed: int = 0,
                    groups: np.ndarray | None = None) -> np.ndarray:
    """Indices of at most ``max_per_class`` points per class (y ≥ 0), drawn at random
    without replacement; every point of a class smaller than the cap.  Sorted."""
    y = np.asarray(y)
    rng = np.random.default_rng(seed)
    out = []
    for c in np.unique(y[y >= 0]):
        ii = np.flatnonzero(y == c)
        if max_per_class and len(ii) > max_per_class:
            ii = rng.choice(ii, int(max_per_class), replace=False)
        out.append(ii)
    return np.sort(np.concatenate(out)) if out else np.zeros(0, np.int64)
