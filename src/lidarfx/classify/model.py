"""Training, prediction and the model file.

A model is a fitted scikit-learn pipeline (:class:`~lidarfx.classify.pipeline.LidarFeatures`
→ NaN handling → classifier) plus what is needed to use it safely: the class map,
the expanded feature list, the radii and feature parameters, the lidarfx and
scikit-learn versions and the training files.  It is saved with **skops**
(no pickle) and loaded with an explicit list of trusted types: a file holding
any other type is refused before anything in it is built.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from .. import __version__
from .._json import jsonable
from ..cloud import PointCloud
from ..errors import LidarfxError, LidarfxWarning, check_seed
from ..progress import stage, wanted
from .classes import DEFAULT_IGNORE, ClassMap
from .pipeline import (
    DEFAULT_HAG_CAP,
    DEFAULT_MAX_DISC_POINTS,
    DEFAULT_RADII,
    RETURN_INPUTS,
    CloudSample,
    LidarFeatures,
    balanced_sample,
    feature_list,
    make_classifier,
    make_imputer,
    point_density,
    point_spacing,
    pulse_thinning_mask,
    return_information,
    spacing_radii,
    terrain_shear,
    unit_to_metre,
    usable_mask,
)

__all__ = ["TrainConfig", "ClassifierModel", "train", "load_model", "read_sources", "Source", "resolve_defaults",
           "model_path", "DEFAULT_MODEL", "FORMAT", "FORMAT_VERSION", "TRUSTED_TYPES"]

FORMAT = "lidarfx-classifier"
FORMAT_VERSION = 1

#: Every type a lidarfx model file may contain.  Before anything is built, the
#: file's schema is read and each type in it must be on this list (skops' own
#: default trust — all scikit-learn estimators — is not relied upon); the
#: estimators found are then checked to be exactly the ones lidarfx writes.
TRUSTED_TYPES: tuple[str, ...] = (
    # containers and scalars
    "builtins.dict", "builtins.list", "builtins.tuple", "builtins.str", "builtins.int", "builtins.float",
    "builtins.bool", "builtins.NoneType",
    "numpy.ndarray", "numpy.dtype", "numpy.float64", "numpy.float32", "numpy.int64", "numpy.int32",
    "numpy.uint64", "numpy.uint8", "numpy.bool_", "numpy.random._generator.Generator",
    # gradient boosting
    "sklearn.ensemble._hist_gradient_boosting.gradient_boosting.HistGradientBoostingClassifier",
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.ensemble._hist_gradient_boosting.binning._BinMapper",
    "sklearn._loss.loss.HalfMultinomialLoss", "sklearn._loss.loss.HalfBinomialLoss",
    "sklearn._loss._loss.CyHalfMultinomialLoss", "sklearn._loss._loss.CyHalfBinomialLoss",
    "sklearn._loss.link.MultinomialLogit", "sklearn._loss.link.LogitLink", "sklearn._loss.link.Interval",
    "sklearn.preprocessing._label.LabelEncoder",
    # random forest
    "sklearn.ensemble._forest.RandomForestClassifier", "sklearn.tree._classes.DecisionTreeClassifier",
    "sklearn.tree._tree.Tree",
    # naive Bayes and its imputer
    "sklearn.naive_bayes.GaussianNB", "sklearn.impute._base.SimpleImputer",
)

DEFAULT_MAX_PER_CLASS = 20_000

#: the model shipped with lidarfx (``--model default``): the default pipeline trained on the three
#: IGN LiDAR HD tiles (ground / vegetation / building); its card is docs/default-model.md, its
#: build script benchmarks/build_default_model.py
DEFAULT_MODEL = Path(__file__).resolve().parent.parent / "data" / "models" / "default.skops"

#: predicted-building clusters with a smaller plan footprint (m²) are given their next most
#: probable class (:mod:`.objects`); chosen on the training tiles (docs/classification-record.md §7).
#: Part of the ALS default: with a feature list of one's own (e.g. TLS) the rule is off unless asked for
DEFAULT_MIN_BUILDING_AREA = 10.0

#: a predicted-building cluster of at least that area in which more than this share of the points
#: come from multi-return pulses is given its next class (see-through test;
#: docs/classification-record.md §8); 1 = no test.  Acts only together with the minimum area above
DEFAULT_MAX_MULTI_RETURN_SHARE = 0.5

#: prediction computes and classifies the features of this many points at a time: the feature
#: matrix of a whole 40-million-point tile (81 float32 columns) would need 13 GB; a chunk needs 0.3 GB
PREDICT_CHUNK = 1_000_000

#: prediction warns when a cloud has less than this share of the sparsest training file's
#: density: on the IGN training tiles (leave one tile out) OA fell by 0.01 at half the
#: density and by 0.03 at a quarter (docs/classification.md §10)
DENSITY_WARN_RATIO = 0.5


def cloud_density(cloud: PointCloud) -> float:
    """Points per m² (all returns, over the occupied 2 m squares; coordinates in metres)."""
    u = unit_to_metre(cloud)
    return point_density(cloud.xyz if u == 1.0 else cloud.xyz * u)


# --------------------------------------------------------------------------- configuration
MAX_TERRAIN_COPIES = 100
"""Most terrain-sheared copies of the training files (each is a whole copy in memory)."""
MAX_ESTIMATORS = 100_000
"""Most trees (rf) or boosting iterations (hgb)."""


@dataclass
class TrainConfig:
    """Everything that defines a model before it sees data (stored in the model file).

    ``radii`` None: 1, 2 and 3 m for spheres and cylinders, none for kNN (whose one radius
    would only cap the neighbour distance); for spheres and cylinders ``auto_radii`` is then
    True and :func:`train` replaces them by radii from the training files' point spacing
    (:func:`resolve_defaults`: 1, 2, 3 m for ALS, smaller for denser clouds).  A stored model's
    ``auto_radii`` says its radii were derived that way."""

    features: list[str] | None = None
    radii: list[float] | None = None
    neighbourhood: str = "sphere"
    k: int | None = None
    scanner: list[float] | None = None
    hist_bins: int = 10
    ground: str = "smrf"
    hag_cap: float | None = DEFAULT_HAG_CAP
    max_disc_points: float | None = DEFAULT_MAX_DISC_POINTS
    terrain_augment: int = 1
    density_augment: list[float] | None = None
    precomputed: bool = False
    classifier: str = "hgb"
    n_estimators: int | None = None
    max_per_class: int | None = DEFAULT_MAX_PER_CLASS
    balance: bool = True
    seed: int = 0
    n_jobs: int | None = None
    min_building_area: float | None = None
    max_multi_return_share: float = DEFAULT_MAX_MULTI_RETURN_SHARE
    auto_radii: bool | None = None

    def __post_init__(self) -> None:
        if isinstance(self.features, str):
            self.features = [f.strip() for f in self.features.split(",") if f.strip()]
        elif self.features is not None:
            self.features = [str(f) for f in self.features]
        if self.auto_radii is None:  # the radii were not given: derived from the point spacing at training
            self.auto_radii = self.radii is None and self.neighbourhood != "knn" and not self.precomputed
        self.auto_radii = bool(self.auto_radii)
        if self.radii is None:
            self.radii = [] if self.neighbourhood == "knn" else list(DEFAULT_RADII)
        self.radii = sorted(set(float(r) for r in self.radii))
        if self.scanner is not None:
            self.scanner = [float(v) for v in self.scanner]
            if len(self.scanner) != 3 or not all(math.isfinite(v) for v in self.scanner):
                raise LidarfxError(f"scanner must be three finite numbers x,y,z, got {self.scanner}")
        if self.hag_cap is not None:
            self.hag_cap = float(self.hag_cap)
            if not self.hag_cap > 0:
                raise LidarfxError(f"hag_cap must be a positive height in m or None, got {self.hag_cap}")
        if self.max_disc_points is not None:
            self.max_disc_points = float(self.max_disc_points)
            if not self.max_disc_points >= 1:  # fewer than one point per disc thinned the cloud away
                raise LidarfxError(f"max_disc_points must be at least 1 point per disc (or None: never thin), "
                                   f"got {self.max_disc_points:g}")
        self.terrain_augment = int(self.terrain_augment or 0)
        if not 0 <= self.terrain_augment <= MAX_TERRAIN_COPIES:
            raise LidarfxError(f"terrain_augment must be a number of copies from 0 to {MAX_TERRAIN_COPIES}, "
                               f"got {self.terrain_augment}")
        if self.n_jobs is not None and not (isinstance(self.n_jobs, (int, np.integer)) and 1 <= self.n_jobs <= 1024):
            raise LidarfxError(f"n_jobs must be a number of threads from 1 to 1024 (or None: automatic), "
                               f"got {self.n_jobs!r}")
        if self.density_augment:
            self.density_augment = [float(f) for f in self.density_augment]
            if not all(0.0 < f < 1.0 for f in self.density_augment):
                raise LidarfxError(f"density_augment takes fractions between 0 and 1 (exclusive), "
                                   f"got {self.density_augment}")
        else:
            self.density_augment = None
        if self.min_building_area is None:  # auto: part of the ALS default only (docs/classification.md §2)
            # (also for "default,-name…": the default list with a few inputs left out)
            default = self.features is None or any(f.strip().lower() == "default" for f in self.features)
            self.min_building_area = DEFAULT_MIN_BUILDING_AREA if default else 0.0
        from .objects import check_area, check_share

        self.min_building_area = check_area(self.min_building_area)
        self.max_multi_return_share = check_share(self.max_multi_return_share)
        self.seed = check_seed(self.seed)
        if self.max_per_class is not None and int(self.max_per_class) < 1:
            raise LidarfxError("max_per_class must be >= 1 (or None for every point)")
        make_classifier(self.classifier)  # validates the kind
        self.classifier = str(self.classifier).lower()
        if self.n_estimators is not None and (self.classifier == "nb"
                                              or not 1 <= int(self.n_estimators) <= MAX_ESTIMATORS):
            raise LidarfxError(f"n_estimators is the number of trees (rf) or boosting iterations (hgb), from 1 to "
                               f"{MAX_ESTIMATORS}; got {self.n_estimators} for classifier {self.classifier!r}")
        feature_list(self.features, self.radii, self.neighbourhood, self.k)  # validates
        from ..features.api import check_hist_bins

        self.hist_bins = check_hist_bins(self.hist_bins)

    def feature_params(self) -> dict[str, Any]:
        return {"features": self.features, "radii": list(self.radii), "neighbourhood": self.neighbourhood,
                "k": self.k, "scanner": self.scanner, "hist_bins": self.hist_bins, "ground": self.ground,
                "hag_cap": self.hag_cap, "max_disc_points": self.max_disc_points,
                "precomputed": self.precomputed}

    def transformer(self, progress: bool | None = False) -> LidarFeatures:
        return LidarFeatures(**self.feature_params(), progress=progress).fit()

    def feature_names(self) -> list[str]:
        return feature_list(self.features, self.radii, self.neighbourhood, self.k)[0]

    def fit_matrix(self, X: np.ndarray, y: np.ndarray, progress: bool | None = None, step: str = ""):
        """Fit NaN handling + classifier on a feature matrix (class-balanced by sample weights);
        ``step`` names the run in the progress spinner (e.g. ``"fold 2 of 5: "``)."""
        from sklearn.pipeline import Pipeline
        from sklearn.utils.class_weight import compute_sample_weight

        if len(np.unique(y)) < 2:
            raise LidarfxError("the training sample holds fewer than two classes")
        tail = Pipeline([("impute", make_imputer(self.classifier)),
                         ("classifier", make_classifier(self.classifier, n_estimators=self.n_estimators,
                                                        random_state=self.seed, n_jobs=self.n_jobs))])
        w = compute_sample_weight("balanced", y) if self.balance else None
        if w is not None and np.allclose(w, w[0]):
            w = None  # a balanced sample needs no weights (and weights double the boosting time)
        with _fit_threads(self), stage(f"{step}fitting {self.classifier} on {len(y):,} points", wanted(progress)):
            tail.fit(X, y, classifier__sample_weight=w)
        return tail

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _fit_threads(cfg: "TrainConfig"):
    """OpenMP threads while fitting gradient boosting: ``n_jobs``, by default :func:`idle_cores`.

    scikit-learn's histogram boosting synchronises its OpenMP threads many times
    per tree; when the cores are shared with other processes the spinning threads
    make a fit 5–20 times slower than on one thread (measured here: 96 s vs 18.5 s).
    So by default it gets only the cores nobody else is using when the fit starts.
    The fitted model does not depend on the thread count.
    """
    import contextlib

    if cfg.classifier != "hgb":
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=int(cfg.n_jobs or idle_cores()), user_api="openmp")


def idle_cores(samples: int = 5, interval: float = 0.01) -> int:
    """Cores this process may use that no other task is running on now (at least 1).

    The cores: joblib's count (CPU affinity and container CPU quotas), at most
    ``OMP_NUM_THREADS`` when that is set.  Busy ones, on Linux: the kernel's count
    of runnable tasks (``/proc/loadavg``, 4th field, which counts the reader
    itself; in a container, the host's), the smallest of ``samples`` readings
    ``interval`` seconds apart, so that short bursts (and this process's own
    threads winding down) do not count.  Elsewhere: one core (no reliable
    instantaneous load).  A process that starts later is not seen.
    """
    if not hasattr(os, "sched_getaffinity"):  # pragma: no cover - not Linux
        return 1
    from joblib import cpu_count

    cores = int(cpu_count())
    omp = os.environ.get("OMP_NUM_THREADS", "").split(",")[0].strip()  # "4,2": nested levels
    if omp.isdigit() and int(omp) > 0:
        cores = min(cores, int(omp))
    if cores < 2:
        return 1
    busy = None
    try:
        for i in range(max(int(samples), 1)):
            if i:
                time.sleep(interval)
            with open("/proc/loadavg") as f:
                running = int(f.read().split()[3].split("/")[0]) - 1  # without the reader
            busy = running if busy is None else min(busy, running)
    except (OSError, ValueError, IndexError):  # pragma: no cover - no procfs
        return 1
    return max(1, cores - max(busy or 0, 0))


# --------------------------------------------------------------------------- sources
@dataclass
class Source:
    """One input cloud, reduced to its usable points (see :func:`usable_mask`)."""

    name: str
    cloud: PointCloud  # usable points only
    usable: np.ndarray  # mask into the original cloud
    n_total: int


def read_sources(sources: Any, progress: bool | None = False) -> list[Source]:
    """Paths or PointClouds → :class:`Source` list (virtual / withheld points dropped)."""
    from .. import io

    if isinstance(sources, (str, os.PathLike, PointCloud, Source)):
        sources = [sources]
    out = []
    for i, s in enumerate(sources):
        if isinstance(s, Source):
            out.append(s)
            continue
        if isinstance(s, PointCloud):
            cloud, name = s, str(s.meta.get("name") or s.meta.get("source") or f"cloud {i + 1}")
        else:
            cloud, name = io.read(s, progress=progress), str(s)
        mask = usable_mask(cloud)
        warn_unusable(cloud, mask, name)
        sub = cloud if mask.all() else cloud.subset(mask)
        sub.meta = {**sub.meta, "name": name}
        out.append(Source(name, sub, mask, len(cloud)))
    if not out:
        raise LidarfxError("no input clouds")
    if not any(len(s.cloud) for s in out):
        names = ", ".join(s.name for s in out)
        raise LidarfxError(f"{names}: no usable points (empty, or only virtual / withheld / synthetic points)")
    return out


def warn_unusable(cloud: PointCloud, mask: np.ndarray, name: str) -> None:
    """Warn when most points are left out (withheld / synthetic flag, return number 0):
    they are neither neighbours, training points nor predicted, which is right for IGN's
    virtual points but surprising when a file sets those flags on real points."""
    n, bad = len(mask), int((~mask).sum())
    if n and bad > n // 2:
        why = [f"{f} {int((np.asarray(cloud[f]) != 0).sum()):,}" for f in ("withheld", "synthetic") if f in cloud]
        if "return_number" in cloud:
            why.append(f"return number 0: {int((np.asarray(cloud['return_number']) == 0).sum()):,}")
        warnings.warn(f"{name}: {bad:,} of {n:,} points are not used (flags: {', '.join(why)}); "
                      "they are neither training points nor classified", LidarfxWarning, stacklevel=3)


def source_labels(src: Source, classes: ClassMap) -> np.ndarray:
    """Class index of every point of ``src`` in ``classes`` (−1: not in the map)."""
    if "classification" not in src.cloud:
        raise LidarfxError(f"{src.name} has no classification: training and evaluation need labelled points")
    return classes.index_of(src.cloud["classification"])


def resolve_classes(sources: list[Source], classes: Any = None, ignore: Iterable[int] | None = None) -> ClassMap:
    """The class map: parsed from ``classes`` or one class per code found, minus ``ignore``
    (without ``classes``, ``ignore`` adds to :data:`DEFAULT_IGNORE`; to keep one of those codes,
    list the classes)."""
    ignore = [] if ignore is None else [int(c) for c in ignore]  # any iterable, numpy arrays too
    if classes is not None:
        cm = ClassMap.parse(classes)
        if ignore:
            cm = cm.without(ignore)
        return cm
    codes: set[int] = set()
    for s in sources:
        if "classification" not in s.cloud:
            raise LidarfxError(f"{s.name} has no classification: training needs labelled points")
        codes |= set(np.unique(s.cloud["classification"]).tolist())
    return ClassMap.from_codes(codes, set(DEFAULT_IGNORE) | set(ignore))


# --------------------------------------------------------------------------- model
class ClassifierModel:
    """A fitted point classifier: ``pipeline`` (scikit-learn), ``classes`` and ``meta``."""

    def __init__(self, pipeline, classes: ClassMap, meta: dict[str, Any]) -> None:
        self.pipeline = pipeline
        self.classes = classes
        self.meta = meta

    # ------------------------------------------------------------------ properties
    @property
    def features(self) -> LidarFeatures:
        return self.pipeline.named_steps["features"]

    @property
    def feature_names(self) -> list[str]:
        return list(self.meta["features"])

    @property
    def radii(self) -> list[float]:
        return list(self.meta["config"]["radii"])

    @property
    def estimator(self):
        """The fitted part after the features (NaN handling + classifier), for scikit-learn tools."""
        return self.pipeline[1:]

    def _fast(self):
        """The numba tree walker for a boosting model (:mod:`.fastpredict`), else None."""
        if not hasattr(self, "_fast_cache"):
            from .fastpredict import fast_estimator

            self._fast_cache = fast_estimator(self.estimator)
        return self._fast_cache

    def proba_matrix(self, X: np.ndarray) -> np.ndarray:
        fast = self._fast()
        return fast.predict_proba(X) if fast is not None else self.estimator.predict_proba(X)

    def predict_matrix(self, X: np.ndarray) -> np.ndarray:
        fast = self._fast()
        return fast.predict(X) if fast is not None else self.estimator.predict(X)

    def __repr__(self) -> str:
        return (f"ClassifierModel({self.meta['config']['classifier']}, classes={self.classes.spec()!r}, "
                f"{len(self.feature_names)} features, radii={self.radii})")

    def summary(self) -> dict[str, Any]:
        """What the model is, from its metadata: classes, features, radii, training data, versions."""
        clf = self.pipeline.named_steps["classifier"]
        size = {}
        if hasattr(clf, "n_iter_"):
            size = {"boosting_iterations": int(clf.n_iter_),
                    "trees": int(clf.n_iter_) * (1 if len(self.classes) == 2 else len(self.classes))}
        elif hasattr(clf, "estimators_"):
            size = {"trees": len(clf.estimators_)}
        tr = self.meta.get("training", {})
        return {
            "classifier": self.meta["config"]["classifier"], **size,
            "classes": [{"name": n, "codes": list(g), "output_code": int(c)}
                        for n, g, c in zip(self.classes.names, self.classes.groups, self.classes.codes)],
            "class_spec": self.classes.spec(),
            "features": self.feature_names,
            "radii": self.radii,
            "min_building_area": self.min_building_area,
            "max_multi_return_share": self.max_multi_return_share,
            "config": self.meta["config"],
            "training_files": tr.get("files", []),
            "training_density": self.training_density,
            "training_counts": tr.get("counts", {}).get("used", {}),
            "training_seconds": tr.get("seconds", {}),
            "defaults": {k: v for k, v in ((self.meta.get("training", {}).get("defaults") or {}).items()) if v},
            "card": self.meta.get("card"),
            "lidarfx_version": self.meta.get("lidarfx_version"),
            "sklearn_version": self.meta.get("sklearn_version"),
            "created": self.meta.get("created"),
        }

    # ------------------------------------------------------------------ prediction
    def check(self, cloud: PointCloud, name: str | None = None) -> None:
        """Refuse a cloud the model cannot classify (no points, missing fields or precomputed features)."""
        name = name or str(cloud.meta.get("name") or cloud.meta.get("source") or "the cloud")
        if len(cloud) == 0:
            raise LidarfxError(f"{name} is empty: no points to classify")
        self.features.check_cloud(cloud, name)

    @property
    def training_density(self) -> float | None:
        """Points per m² of the sparsest training file (None for models that did not record it)."""
        d = self.meta.get("training", {}).get("density")
        return float(d) if d else None

    def density_check(self, cloud: PointCloud, name: str | None = None, warn: bool = True
                      ) -> dict[str, Any] | None:
        """Compare the density of ``cloud`` (usable points) with the training files'.

        Returns ``{"density", "training_density", "ratio"}`` (points per m²), or None when
        the model did not record a density or the cloud is empty.  With ``warn`` a
        :class:`~lidarfx.errors.LidarfxWarning` is issued when the ratio is below
        :data:`DENSITY_WARN_RATIO`: the neighbourhoods then hold fewer points than in
        training and the features, hence the classes, change.  Denser clouds are
        thinned to the training density by the features themselves.
        """
        ref = self.training_density
        usable = usable_mask(cloud)
        if ref is None or not usable.any():
            return None
        d = cloud_density(cloud if usable.all() else cloud.subset(usable))
        info = {"density": round(d, 2), "training_density": round(ref, 2), "ratio": round(d / ref, 3)}
        if warn and d < DENSITY_WARN_RATIO * ref:
            label = name or str(cloud.meta.get("name") or cloud.meta.get("source") or "the cloud")
            warnings.warn(
                f"{label}: {d:.1f} points/m² is {d / ref:.0%} of the sparsest training file's {ref:.1f}; "
                "the model's neighbourhoods were learned on denser data and accuracy falls with density "
                "(train on data like this, or with --density-augment)", LidarfxWarning, stacklevel=2)
        return info

    def feature_chunks(self, cloud: PointCloud, index: np.ndarray | None = None, chunk: int | None = None,
                       progress: bool | None = False) -> Iterator[tuple[slice, np.ndarray]]:
        """``(rows, X)`` for consecutive chunks of ``index`` (default all points): the features of
        ``chunk`` (default :data:`PREDICT_CHUNK`) query points at a time, so memory stays bounded on
        large clouds (every point of ``cloud`` is a neighbour; the height above ground is computed once)."""
        chunk = int(chunk or PREDICT_CHUNK)
        tr = self.features
        tr.progress = progress
        names, slots, point, rs = tr.feature_plan()
        self.check(cloud)
        idx = np.arange(len(cloud)) if index is None else np.asarray(index)
        cache: dict = {}
        for a in range(0, len(idx), chunk):
            yield slice(a, min(a + chunk, len(idx))), tr.feature_matrix(CloudSample(cloud, idx[a:a + chunk]), names, slots,
                                                                  point, rs, cache)

    def feature_matrix(self, cloud: PointCloud, index: np.ndarray | None = None, chunk: int | None = None,
                       progress: bool | None = False) -> np.ndarray:
        """Features of ``cloud`` (rows ``index``, default all) as the model computes them."""
        blocks = [X for _, X in self.feature_chunks(cloud, index, chunk, progress)]
        if not blocks:
            return np.empty((0, len(self.feature_names)), np.float32)
        return np.vstack(blocks) if len(blocks) > 1 else blocks[0]

    def predict_proba(self, cloud: PointCloud, *, progress: bool | None = False, check_density: bool = True
                      ) -> tuple[np.ndarray, np.ndarray]:
        """``(proba, usable)``: class probabilities (n_usable × k) of the usable points and the mask
        (``check_density``: as in :meth:`predict`).  Features are computed and classified one chunk
        of :data:`PREDICT_CHUNK` points at a time; only the probabilities are kept."""
        if check_density:
            self.density_check(cloud)
        usable = usable_mask(cloud)
        sub = cloud if usable.all() else cloud.subset(usable)
        proba = np.empty((len(sub), len(self.classes)), dtype=np.float64)
        for rows, X in self.feature_chunks(sub, progress=progress):
            proba[rows] = self.proba_matrix(X)
        return proba, usable

    @property
    def min_building_area(self) -> float:
        """Minimum plan area (m²) of a predicted building cluster (:mod:`.objects`; 0 = no rule;
        models written before the rule existed have 0)."""
        return float(self.meta["config"].get("min_building_area") or 0.0)

    def set_min_building_area(self, area: float) -> None:
        """Change the object-size rule of this model (m²; 0 = off); kept when the model is saved."""
        from .objects import check_area

        area = check_area(area)
        self.meta = {**self.meta, "config": {**self.meta["config"], "min_building_area": area}}

    @property
    def max_multi_return_share(self) -> float:
        """Largest share of points from multi-return pulses that a predicted building cluster of at
        least :attr:`min_building_area` may have (the see-through test of :mod:`.objects`; 1 = no
        test; models written before the test existed have 1)."""
        return float(self.meta["config"].get("max_multi_return_share") or 1.0)

    def set_max_multi_return_share(self, share: float) -> None:
        """Change the see-through test of this model (a share in (0, 1]; 1 = off); kept when saved."""
        from .objects import check_share

        share = check_share(share)
        self.meta = {**self.meta, "config": {**self.meta["config"], "max_multi_return_share": share}}

    def predict(self, cloud: PointCloud, *, progress: bool | None = False, return_confidence: bool = False,
                check_density: bool = True, min_building_area: float | None = None,
                max_multi_return_share: float | None = None, stats: dict | None = None,
                return_proba: bool = False):
        """Output class code of every point (int16); −1 where not predicted (virtual /
        withheld / synthetic points).  With ``return_confidence`` also the probability of
        the class given (float32, NaN where not predicted), and with ``return_proba`` last
        the classifier's probabilities of every class (float32, n × classes in the order of
        :attr:`classes`, before the building rule below; NaN rows where not predicted), so
        ``codes, conf, proba`` with both.  ``check_density``:
        warn when the cloud is much sparser than the training data (:meth:`density_check`).

        Predicted-building clusters smaller than ``min_building_area`` m² (default: the
        model's, :attr:`min_building_area`; 0 = off) that do not reach the cloud's edge
        get their next most probable class, and so do the larger ones in which more than
        ``max_multi_return_share`` (default: the model's) of the points come from pulses
        with several returns (:func:`.objects.drop_small_objects`; its counts go into
        ``stats``).  :meth:`predict_proba` returns the probabilities before this rule."""
        from .objects import building_class, drop_small_objects, link_for

        if check_density:
            self.density_check(cloud)
        area = self.min_building_area if min_building_area is None else float(min_building_area)
        share = self.max_multi_return_share if max_multi_return_share is None else float(max_multi_return_share)
        target = building_class(self.classes) if area > 0 else None
        usable = usable_mask(cloud)
        sub = cloud if usable.all() else cloud.subset(usable)
        k = np.empty(len(sub), dtype=np.int64)
        best = np.empty(len(sub), dtype=np.float32) if return_confidence else None
        alt = np.empty(len(sub), dtype=np.int16) if target is not None else None
        alt_p = np.empty(len(sub), dtype=np.float32) if (alt is not None and best is not None) else None
        every = np.empty((len(sub), len(self.classes)), dtype=np.float32) if return_proba else None
        for rows, X in self.feature_chunks(sub, progress=progress):  # bounded memory on large clouds
            if best is None and alt is None and every is None:
                k[rows] = self.predict_matrix(X)
                continue
            proba = self.proba_matrix(X)
            k[rows] = proba.argmax(axis=1)
            if every is not None:
                every[rows] = proba
            if best is not None:
                best[rows] = proba[np.arange(len(proba)), k[rows]]
            if alt is not None:
                proba[:, target] = -1.0
                alt[rows] = proba.argmax(axis=1)
                if alt_p is not None:
                    alt_p[rows] = proba.max(axis=1)
        if target is not None:
            u = unit_to_metre(sub)
            xyz = sub.xyz * u if u != 1.0 else sub.xyz
            returns = np.asarray(sub["number_of_returns"]) if "number_of_returns" in sub else None
            new = drop_small_objects(k, alt, xyz, target, area, link=link_for(point_density(xyz)), returns=returns,
                                     max_multi_return_share=share, stats=stats)
            if alt_p is not None:
                changed = new != k
                best[changed] = alt_p[changed]
            k = new
        elif stats is not None:
            stats.clear()
        codes = np.full(len(cloud), -1, dtype=np.int16)
        codes[usable] = self.classes.code_of(k)
        out: list[np.ndarray] = [codes]
        if best is not None:
            conf = np.full(len(cloud), np.nan, dtype=np.float32)
            conf[usable] = best
            out.append(conf)
        if every is not None:
            proba_all = np.full((len(cloud), len(self.classes)), np.nan, dtype=np.float32)
            proba_all[usable] = every
            out.append(proba_all)
        return out[0] if len(out) == 1 else tuple(out)

    def probability_names(self) -> list[str]:
        """The attribute names :meth:`classify` gives the class probabilities:
        ``probability_<class name>`` (lower case, other characters than letters, digits and
        ``_`` made ``_``), or ``probability_<code>`` for every class when a name would not fit
        the 32 characters of a LAS extra dimension or two names would be the same."""
        import re

        names = ["probability_" + re.sub(r"[^0-9a-z_]", "_", str(n).lower()) for n in self.classes.names]
        if len(set(names)) < len(names) or max(len(n) for n in names) > 32:
            names = [f"probability_{int(c)}" for c in self.classes.codes]
        return names

    def classify(self, cloud: PointCloud, *, confidence: bool = False, probabilities: bool = False,
                 progress: bool | None = False) -> PointCloud:
        """A copy of ``cloud`` with ``classification`` set to the predicted codes (points
        not predicted keep their class, or get 1 = unclassified); optionally a
        float32 ``confidence`` attribute (the probability of the class given) and, with
        ``probabilities``, one float32 attribute per class (:meth:`probability_names`: the
        classifier's probabilities, before the building rule; NaN where not predicted)."""
        warn_unusable(cloud, usable_mask(cloud), str(cloud.meta.get("name") or cloud.meta.get("source") or "the cloud"))
        dens = self.density_check(cloud)
        rule: dict[str, Any] = {}
        res = self.predict(cloud, progress=progress, return_confidence=confidence, check_density=False,
                           stats=rule, return_proba=probabilities)
        res = list(res) if isinstance(res, tuple) else [res]
        codes = res.pop(0)
        conf = res.pop(0) if confidence else None
        proba = res.pop(0) if probabilities else None
        out = cloud.copy() if hasattr(cloud, "copy") else PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
        old = out.get("classification")
        cls = np.where(codes >= 0, codes, np.asarray(old) if old is not None else 1).astype(np.uint8)
        out["classification"] = cls
        if conf is not None:
            out["confidence"] = conf
        if proba is not None:
            for j, name in enumerate(self.probability_names()):
                out[name] = np.ascontiguousarray(proba[:, j])
        out.meta = {**out.meta, "classify": {"model_classes": self.classes.spec(),
                                             "predicted_points": int((codes >= 0).sum()),
                                             "density": dens,
                                             "min_building_area": self.min_building_area,
                                             "max_multi_return_share": self.max_multi_return_share,
                                             "small_buildings": rule or None}}
        return out

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write the model with skops (atomic; the zip members deflated: a boosting model's node
        arrays shrink to about a third)."""
        import zipfile

        import skops.io as sio

        from .._atomic import atomic_path

        tail = self.estimator
        obj = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "lidarfx_version": __version__,
            "sklearn_version": _sklearn_version(),
            "meta": jsonable(self.meta),
            "impute": tail.named_steps["impute"],
            "classifier": tail.named_steps["classifier"],
        }
        p = Path(path)
        with atomic_path(p) as tmp:
            sio.dump(obj, tmp, compression=zipfile.ZIP_DEFLATED, compresslevel=9)
        return p

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ClassifierModel":
        return load_model(path)


def _sklearn_version() -> str:
    import sklearn

    return sklearn.__version__


MAX_MODEL_BYTES = 2**31
"""A model file that would unpack to more bytes than this is refused unread (the shipped model: 5 MB)."""
MAX_ZIP_RATIO = 500
"""A member of a model file (over 1 MiB) that packs more tightly than this is refused unread."""


def file_types(path: str | os.PathLike) -> set[str]:
    """Every ``module.class`` named in a skops file's schema (read without building anything)."""
    import json
    import zipfile

    def walk(o: Any, acc: set[str]) -> None:
        if isinstance(o, dict):
            if "__class__" in o and "__module__" in o:
                acc.add(f"{o['__module__']}.{o['__class__']}")
            for v in o.values():
                walk(v, acc)
        elif isinstance(o, list):
            for v in o:
                walk(v, acc)

    try:
        with zipfile.ZipFile(path) as z:
            infos = z.infolist()
            total = sum(i.file_size for i in infos)
            bomb = total > MAX_MODEL_BYTES or any(i.file_size > 2**20 and i.file_size > MAX_ZIP_RATIO * i.compress_size
                                                  for i in infos)
            if not bomb:
                schema = json.loads(z.read("schema.json"))
    except Exception as exc:  # also RecursionError (nested too deeply) and huge integers (ValueError)
        raise LidarfxError(f"{path}: not a skops model file ({type(exc).__name__}: {str(exc)[:200]})") from None
    if bomb:
        raise LidarfxError(f"{path}: refusing to load: it would unpack to {total:,} bytes (a lidarfx model is far "
                           f"smaller and packs at most {MAX_ZIP_RATIO}:1)")
    acc: set[str] = set()
    walk(schema, acc)
    return acc


def untrusted_types(path: str | os.PathLike) -> list[str]:
    """Types in a skops file that are not in :data:`TRUSTED_TYPES` (empty = safe to load)."""
    return sorted(t for t in file_types(path) if t not in TRUSTED_TYPES)


def model_path(path: str | os.PathLike) -> Path:
    """The file of a model name: ``"default"`` is the model shipped with lidarfx
    (:data:`DEFAULT_MODEL`; a file called ``default`` is ``./default``), anything else a path."""
    if str(path) == "default":
        if not DEFAULT_MODEL.is_file():
            raise LidarfxError(f"the default model is not installed ({DEFAULT_MODEL} is missing); rebuild it with "
                               "python benchmarks/build_default_model.py, or give a model file")
        return DEFAULT_MODEL
    return Path(path)


def load_model(path: str | os.PathLike) -> ClassifierModel:
    """Load a model saved by :meth:`ClassifierModel.save` without executing code.

    ``path`` ``"default"`` loads the model shipped with lidarfx (:func:`model_path`,
    docs/default-model.md).

    The types named in the file are listed first; if any is not in
    :data:`TRUSTED_TYPES` the file is refused (:class:`LidarfxError`) and
    nothing in it is built.  Then skops loads it with exactly those types
    trusted, and the estimators are checked to be the kinds lidarfx writes.
    """
    import skops.io as sio
    from sklearn.ensemble import HistGradientBoostingClassifier, RandomForestClassifier
    from sklearn.impute import SimpleImputer
    from sklearn.naive_bayes import GaussianNB
    from sklearn.pipeline import Pipeline

    p = model_path(path)
    if not p.is_file():
        raise LidarfxError(f"model file not found: {p}")
    bad = untrusted_types(p)
    if bad:
        raise LidarfxError(f"{p}: refusing to load: the file contains types a lidarfx model never holds: "
                           f"{', '.join(bad[:5])}")
    try:
        trusted = [t for t in sio.get_untrusted_types(file=p) if t in TRUSTED_TYPES]
        obj = sio.load(p, trusted=trusted)
    except Exception as exc:
        raise LidarfxError(f"{p}: cannot load the model ({type(exc).__name__}: {exc})") from None
    if not isinstance(obj, dict) or obj.get("format") != FORMAT:
        raise LidarfxError(f"{p}: not a lidarfx classifier model")
    if obj.get("format_version") != FORMAT_VERSION:
        raise LidarfxError(f"{p}: model format {obj.get('format_version')} is not supported "
                           f"(this lidarfx reads format {FORMAT_VERSION})")
    clf, imp = obj.get("classifier"), obj.get("impute")
    if type(clf) not in (HistGradientBoostingClassifier, RandomForestClassifier, GaussianNB):
        raise LidarfxError(f"{p}: unexpected classifier type {type(clf).__name__}")
    if not (imp == "passthrough" or type(imp) is SimpleImputer):
        raise LidarfxError(f"{p}: unexpected preprocessing step {type(imp).__name__}")
    meta = obj["meta"]
    if obj.get("lidarfx_version") != __version__:
        warnings.warn(f"{p} was written by lidarfx {obj.get('lidarfx_version')}, this is {__version__}; "
                      "features may differ", LidarfxWarning, stacklevel=2)
    if obj.get("sklearn_version") != _sklearn_version():
        warnings.warn(f"{p} was written with scikit-learn {obj.get('sklearn_version')}, this is "
                      f"{_sklearn_version()}", LidarfxWarning, stacklevel=2)
    try:
        stored = dict(meta["config"])
        # settings the configuration ignored before it refused them (a k without kNN, trees for naive Bayes)
        if stored.get("neighbourhood", "sphere") != "knn":
            stored["k"] = None
        if stored.get("classifier") == "nb":
            stored["n_estimators"] = None
        config = TrainConfig(**stored)
        names = config.feature_names()
        classes = ClassMap.from_dict(meta["classes"])
    except (KeyError, TypeError) as exc:
        raise LidarfxError(f"{p}: incomplete model metadata ({exc})") from None
    if names != list(meta["features"]):
        raise LidarfxError(f"{p}: the stored feature list does not match its feature parameters "
                           "(file edited, or written by an incompatible lidarfx)")
    n_in = getattr(clf, "n_features_in_", len(names))
    if n_in != len(names):
        raise LidarfxError(f"{p}: the classifier expects {n_in} features but the model lists {len(names)}")
    if len(getattr(clf, "classes_", range(len(classes)))) != len(classes):
        raise LidarfxError(f"{p}: the classifier knows {len(clf.classes_)} classes, the class map {len(classes)}")
    pipe = Pipeline([("features", config.transformer()), ("impute", imp), ("classifier", clf)])
    return ClassifierModel(pipe, classes, meta)


# --------------------------------------------------------------------------- training
AUGMENT_SHARE = 0.5
"""Training points drawn per class from each terrain-sheared copy, relative to ``max_per_class``."""


def augment_cap(cfg: TrainConfig) -> int | None:
    """Training points drawn per class from each augmented copy (None: all)."""
    return None if cfg.max_per_class is None else max(1, int(cfg.max_per_class * AUGMENT_SHARE))


def sheared_sources(srcs: list[Source], cfg: TrainConfig) -> list[list[Source]]:
    """``cfg.terrain_augment`` lists of terrain-sheared copies of the sources (training augmentation,
    see :func:`~lidarfx.classify.pipeline.terrain_shear`); seeded by ``cfg.seed``."""
    out = []
    for a in range(cfg.terrain_augment):
        out.append([Source(s.name + f" (sheared {a + 1})", terrain_shear(s.cloud, seed=cfg.seed * 7919 + 31 * a + i),
                           s.usable, s.n_total) for i, s in enumerate(srcs)])
    return out


def thinned_sources(srcs: list[Source], cfg: TrainConfig) -> list[list[tuple[Source, np.ndarray]]]:
    """For each fraction of ``cfg.density_augment``: thinned copies of the sources (whole pulses
    kept with that probability, :func:`~lidarfx.classify.pipeline.pulse_thinning_mask`) and
    their masks over the source points; seeded by ``cfg.seed``.  Training augmentation for
    models that must classify sparser clouds than the training files."""
    out = []
    for b, f in enumerate(cfg.density_augment or []):
        copies = []
        for i, s in enumerate(srcs):
            m = pulse_thinning_mask(s.cloud, f, seed=cfg.seed * 7919 + 1009 + 31 * b + i)
            c = s.cloud.subset(m)
            c.meta = {**c.meta, "name": f"{s.name} (thinned to {f:g})"}
            copies.append((Source(c.meta["name"], c, s.usable, s.n_total), m))
        out.append(copies)
    return out


def labelled_sample(sources: list[Source], classes: ClassMap, max_per_class: int | None, seed: int
                    ) -> tuple[list[CloudSample], np.ndarray, dict[str, Any]]:
    """Balanced training sample over all sources: (samples, y, per-class counts)."""
    ys = [source_labels(s, classes) for s in sources]
    y_all = np.concatenate(ys) if ys else np.zeros(0, np.int16)
    pick = balanced_sample(y_all, max_per_class, seed)
    bounds = np.cumsum([0] + [len(y) for y in ys])
    samples, yy = [], []
    for i, s in enumerate(sources):
        sel = pick[(pick >= bounds[i]) & (pick < bounds[i + 1])] - bounds[i]
        if len(sel):
            samples.append(CloudSample(s.cloud, sel))
            yy.append(ys[i][sel])
    y = np.concatenate(yy) if yy else np.zeros(0, np.int16)
    counts = {
        "available": {classes.names[c]: int((y_all == c).sum()) for c in range(len(classes))},
        "used": {classes.names[c]: int((y == c).sum()) for c in range(len(classes))},
    }
    missing = [classes.names[c] for c in range(len(classes)) if not (y == c).any()]
    if missing:
        present: set[int] = set()
        for s in sources:
            if "classification" in s.cloud:
                present |= set(np.unique(np.asarray(s.cloud["classification"])[usable_mask(s.cloud)]).tolist())
        raise LidarfxError(f"no training points of {', '.join(repr(m) for m in missing)} (the usable points "
                           f"hold the classes {sorted(present) or 'none'}; check --classes)")
    return samples, y.astype(np.int64), counts


def resolve_defaults(config: TrainConfig, sources: list[Source], log: Callable[[str], None] | None = None
                     ) -> tuple[TrainConfig, dict[str, Any]]:
    """The configuration :func:`train` uses on these training files: ``config`` with its defaults
    fitted to the data, and what was done (``{"returns": …, "spacing": …}``, stored in the model).

    * **Return numbers.** With the default feature list (``features`` None), when a training file
      has no return numbers (fields missing or 0 in every point: TLS / MLS scans, AHN4 exports) or
      no file has more than one return per pulse (every point 1 of 1), the list becomes
      ``default,-return_ratio,-number_of_returns``: those inputs cannot be computed, or would be
      constant.  One line to ``log`` (without ``log``: a :class:`LidarfxWarning`).  A list given
      explicitly is never changed (a missing field is refused with a hint, as before).
    * **Radii.** With radii not given (``auto_radii``), the radii come from the point spacing of the
      sparsest training file (:func:`~lidarfx.classify.pipeline.point_spacing`, usable points, metres):
      :func:`~lidarfx.classify.pipeline.spacing_radii` — 1, 2, 3 m for ALS (spacing ≥ 0.16 m), r, 2r, 3r
      for denser clouds with r the radius of a disc holding 125 points.  One line to ``log``.
    """
    import dataclasses

    notes: dict[str, Any] = {"returns": None, "spacing": None}
    cfg = config
    if cfg.features is None:
        info = {s.name: return_information(s.cloud) for s in sources}
        lacking = [n for n, v in info.items() if v == "none"]
        if lacking or not any(v == "multi" for v in info.values()):
            spec = ["default"] + ["-" + n for n in RETURN_INPUTS]
            cfg = dataclasses.replace(cfg, features=spec)
            named = lacking or list(info)
            what = ("no return numbers (fields missing or 0 in every point)" if lacking
                    else "only single returns (every point 1 of 1)")
            msg = (f"{what} in {', '.join(named[:3])}{f' and {len(named) - 3} more' if len(named) > 3 else ''}: "
                   f"the default features leave out {', '.join(RETURN_INPUTS)} (--features {','.join(spec)})")
            notes["returns"] = {"files": info, "features": spec, "note": msg}
            if log is not None:
                log("note: " + msg)
            else:
                warnings.warn(msg, LidarfxWarning, stacklevel=3)
    if cfg.auto_radii and cfg.neighbourhood != "knn" and not cfg.precomputed:
        spacing = {}
        for s in sources:
            u = unit_to_metre(s.cloud)
            spacing[s.name] = round(point_spacing(s.cloud.xyz if u == 1.0 else s.cloud.xyz * u), 4)
        sparsest = max(spacing, key=spacing.get)
        radii = spacing_radii(spacing[sparsest])
        if radii != list(cfg.radii):
            cfg = dataclasses.replace(cfg, radii=radii, auto_radii=True)
        notes["spacing"] = {"files": spacing, "spacing": spacing[sparsest], "file": sparsest, "radii": list(cfg.radii),
                            "rule": "1, 2, 3 m unless a 1 m disc holds more than 125 points at the sparsest training "
                                    "file's spacing; then r, 2r, 3r with r the radius of a disc holding 125"}
        if log is not None:
            log(f"radii {', '.join(f'{r:g}' for r in cfg.radii)} m from the point spacing "
                f"({spacing[sparsest]:.3g} m{f', {sparsest}' if len(spacing) > 1 else ''}"
                + ("; the ALS radii" if list(cfg.radii) == list(DEFAULT_RADII) else "") + ")")
    return cfg, notes


def train(
    sources: Any,
    *,
    classes: Any = None,
    ignore: Iterable[int] | None = None,
    config: TrainConfig | None = None,
    progress: bool | None = False,
    log: Callable[[str], None] | None = None,
    **params: Any,
) -> ClassifierModel:
    """Train a point classifier on labelled clouds.

    Parameters
    ----------
    sources:
        Paths or :class:`~lidarfx.PointCloud` objects with a ``classification``.
    classes:
        Class map (``"2,3+4+5,6"``; see :class:`ClassMap`); default: one class
        per code found, minus 0, 1, 7, 18 and the codes in ``ignore``.  With ``classes``,
        ``ignore`` removes codes from its groups.
    config, **params:
        A :class:`TrainConfig`, or its fields as keywords: ``features``,
        ``radii``, ``classifier`` (``hgb``/``rf``/``nb``), ``max_per_class``
        (training points drawn per class, default 20 000), ``balance``
        (class-balanced sample weights, default True), ``seed``, ...

    Returns
    -------
    ClassifierModel
    """
    t0 = time.perf_counter()
    cfg = config or TrainConfig(**params)
    if config is not None and params:
        raise LidarfxError("give either config= or keyword parameters, not both")
    say = log or (lambda msg: None)
    srcs = read_sources(sources, progress=progress)
    cmap = resolve_classes(srcs, classes, ignore)
    cfg, defaults = resolve_defaults(cfg, srcs, log)
    samples, y, counts = labelled_sample(srcs, cmap, cfg.max_per_class, cfg.seed)
    say(f"training sample: {len(y):,} points from {len(srcs)} file(s): "
        + ", ".join(f"{k} {v:,}" for k, v in counts["used"].items()))
    tr = cfg.transformer(progress=progress)
    t1 = time.perf_counter()
    X = tr.transform(samples)
    for a, copies in enumerate(sheared_sources(srcs, cfg)):
        s2, y2, c2 = labelled_sample(copies, cmap, augment_cap(cfg), cfg.seed + 1 + a)
        X = np.vstack([X, tr.transform(s2)])
        y = np.concatenate([y, y2])
        for name, v in c2["used"].items():
            counts["used"][name] += v
        counts.setdefault("terrain_augment", []).append(c2["used"])
    for b, copies in enumerate(thinned_sources(srcs, cfg)):
        s3, y3, c3 = labelled_sample([c for c, _ in copies], cmap, augment_cap(cfg),
                                     cfg.seed + 1 + cfg.terrain_augment + b)  # the seeds evaluate uses
        X = np.vstack([X, tr.transform(s3)])
        y = np.concatenate([y, y3])
        for name, v in c3["used"].items():
            counts["used"][name] += v
        counts.setdefault("density_augment", []).append(c3["used"])
    t2 = time.perf_counter()
    say(f"features: {X.shape[1]} columns of {len(y):,} points in {t2 - t1:.1f} s"
        + (f" (incl. {cfg.terrain_augment} terrain-sheared cop{'y' if cfg.terrain_augment == 1 else 'ies'})"
           if cfg.terrain_augment else "")
        + (f" (incl. copies thinned to {', '.join(f'{f:g}' for f in cfg.density_augment)} of the density)"
           if cfg.density_augment else ""))
    tail = cfg.fit_matrix(X, y, progress)
    t3 = time.perf_counter()
    say(f"fit {cfg.classifier}: {t3 - t2:.1f} s")
    from sklearn.pipeline import Pipeline

    pipe = Pipeline([("features", tr), ("impute", tail.named_steps["impute"]),
                     ("classifier", tail.named_steps["classifier"])])
    meta = {
        "config": cfg.to_dict(),
        "features": cfg.feature_names(),
        "classes": cmap.to_dict(),
        "class_spec": cmap.spec(),
        "training": {
            "files": [{"name": s.name, "points": s.n_total, "usable": len(s.cloud),
                       "density": round(cloud_density(s.cloud), 2)} for s in srcs],
            "density": round(min(cloud_density(s.cloud) for s in srcs), 2),
            "counts": counts,
            "seconds": {"read": round(t1 - t0, 3), "features": round(t2 - t1, 3), "fit": round(t3 - t2, 3)},
            "defaults": defaults,
        },
        "lidarfx_version": __version__,
        "sklearn_version": _sklearn_version(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    return ClassifierModel(pipe, cmap, meta)
