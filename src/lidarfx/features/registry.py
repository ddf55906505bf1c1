"""Feature names and groups → what the kernels compute.

``resolve(["eigen", "slope"])`` returns the ordered neighbourhood slots and
the per-point features (``return_ratio``) a request needs.  Group names,
single feature names and ``all`` may be mixed, and ``-name`` takes a group or a
feature out of what came before it (``all,-quadric``); unknown names raise a
:class:`~lidarfx.errors.LidarfxError` listing what exists.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

from ..errors import LidarfxError
from . import slots as S

#: per-point features that need no neighbourhood
POINT_FEATURES = {"echo": ("return_ratio",), "ground": ("height_above_ground",)}
POINT_NAMES = {n for names in POINT_FEATURES.values() for n in names}

#: what ``--features`` means when not given
DEFAULT_FEATURES = ("eigen", "plane", "density")

#: ``all`` = every neighbourhood group (eigenvector and count helpers included) and
#: return_ratio; height_above_ground (it may run the ground filter) only when asked for
ALL_GROUPS = tuple(S.GROUPS) + ("echo",)


@dataclass(frozen=True)
class Request:
    slots: tuple[int, ...]  # neighbourhood features, in output order
    point: tuple[str, ...]  # per-point features

    @property
    def names(self) -> list[str]:
        return [S.NAMES[s] for s in self.slots] + list(self.point)

    @property
    def need_cylinder(self) -> bool:
        return any(s in S.CYLINDER_SLOTS for s in self.slots)

    @property
    def need_pass2(self) -> bool:
        return any(s in S.PASS2_SLOTS for s in self.slots)

    @property
    def need_msac(self) -> bool:
        return any(s in S.MSAC_SLOTS for s in self.slots)

    @property
    def need_engine(self) -> bool:
        return any(s not in S.MSAC_SLOTS for s in self.slots)


def available() -> dict[str, list[str]]:
    """Group name → feature names (for ``--help`` and error messages)."""
    out = {g: [S.NAMES[s] for s in slots] for g, slots in S.GROUPS.items()}
    out.update({g: list(n) for g, n in POINT_FEATURES.items()})
    return out


def resolve(features: str | Iterable[str] | None, *, allow_empty: bool = False) -> Request:
    """Turn group / feature names (or a comma-separated string) into a :class:`Request`.

    Tokens are read from left to right; ``-name`` takes a group or a feature out of
    what the tokens before it asked for (``all,-eigen,linearity`` keeps ``linearity``).
    ``allow_empty``: return an empty request instead of refusing it (a caller that
    adds inputs of its own checks the whole list).
    """
    if features is None:
        features = DEFAULT_FEATURES
    if isinstance(features, str):
        features = [f for f in features.split(",")]
    slots: list[int] = []
    point: list[str] = []
    index = {name: i for i, name in enumerate(S.NAMES)}

    def add_slot(s: int) -> None:
        if s not in slots:
            slots.append(s)

    for raw in features:
        name = raw.strip().lower()
        if not name:
            continue
        if name.startswith("-"):  # "-quadric", "-slope": leave a group or a feature out
            d = name[1:].strip()
            if not d:
                raise LidarfxError("'-' must be followed by the group or feature to leave out")
            if d.startswith("-"):
                raise LidarfxError(f"{raw.strip()!r}: one '-' leaves a group or a feature out")
            out = resolve([d])  # a group or a feature name (unknown names raise)
            if not set(out.slots) & set(slots) and not set(out.point) & set(point):
                raise LidarfxError(f"cannot leave out {d!r}: it is not among the features requested before it")
            slots[:] = [s for s in slots if s not in out.slots]
            point[:] = [p for p in point if p not in out.point]
            continue
        if name == "all":
            for g in ALL_GROUPS:
                for s in S.GROUPS.get(g, ()):
                    add_slot(s)
                for p in POINT_FEATURES.get(g, ()):
                    if p not in point:
                        point.append(p)
        elif name in S.GROUPS:
            for s in S.GROUPS[name]:
                add_slot(s)
        elif name in POINT_FEATURES:
            point += [p for p in POINT_FEATURES[name] if p not in point]
        elif name in index:
            add_slot(index[name])
        elif name in POINT_NAMES:
            if name not in point:
                point.append(name)
        elif name == "default":
            raise LidarfxError("'default' adds the classifier's default list (lidarfx classify --features) and "
                               "cannot be left out; the feature engine's default is eigen,plane,density")
        else:
            groups = ", ".join(list(S.GROUPS) + list(POINT_FEATURES))
            raise LidarfxError(
                f"unknown feature {raw.strip()!r}; groups: {groups}, all; "
                "or any single feature name (see docs/features.md)"
            )
    if not slots and not point and not allow_empty:
        left = any(str(t).strip().startswith("-") for t in features)
        raise LidarfxError("no features requested" + (" (all were left out)" if left else ""))
    return Request(tuple(slots), tuple(point))
