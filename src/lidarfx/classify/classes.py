"""Class maps: which reference classes are learnt, merged or ignored.

A class map is written like ``2,3+4+5,6``: a comma-separated list of output
classes, each one or several source codes joined by ``+`` (merged), optionally
named (``ground=2,vegetation=3+4+5,building=6``).  The output code of a merged
class is its highest source code (``3+4+5`` → 5: high vegetation, the class a
merged vegetation mostly is in ALS) unless given after a colon
(``vegetation=3+4+5:3``).  Every code that is not listed is **ignored**: never
used for training, never counted in an evaluation (the classifier still labels
those points when it predicts).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from ..errors import LidarfxError

__all__ = ["ClassMap", "ASPRS_NAMES", "DEFAULT_IGNORE"]

#: names of the ASPRS LAS 1.4 standard classes (and the IGN LiDAR HD extras)
ASPRS_NAMES: dict[int, str] = {
    0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
    4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low noise",
    8: "model key point", 9: "water", 10: "rail", 11: "road surface", 12: "overlap",
    13: "wire guard", 14: "wire conductor", 15: "transmission tower", 16: "wire connector",
    17: "bridge deck", 18: "high noise",
}

#: classes left out when no class list is given: never classified, unclassified, noise
DEFAULT_IGNORE: tuple[int, ...] = (0, 1, 7, 18)

_ITEM = re.compile(r"^(?:(?P<name>[A-Za-z_][\w ./-]*?)\s*=\s*)?(?P<codes>\d+(?:\s*\+\s*\d+)*)(?:\s*:\s*(?P<out>\d+))?$")


@dataclass(frozen=True)
class ClassMap:
    """Output classes, each a group of source codes, with an output code and a name."""

    groups: tuple[tuple[int, ...], ...]
    codes: tuple[int, ...]
    names: tuple[str, ...]

    def __post_init__(self) -> None:
        if not self.groups:
            raise LidarfxError("the class map is empty: give at least two classes, e.g. 2,3+4+5,6")
        if not (len(self.groups) == len(self.codes) == len(self.names)):
            raise LidarfxError("class map: groups, codes and names must have the same length")
        seen: set[int] = set()
        for g in self.groups:
            for c in g:
                if not 0 <= c <= 255:
                    raise LidarfxError(f"class codes must be 0..255, got {c}")
                if c in seen:
                    raise LidarfxError(f"class {c} appears twice in the class map")
                seen.add(c)
        if len(set(self.codes)) != len(self.codes):
            raise LidarfxError(f"two output classes share a code: {list(self.codes)}")

    # ------------------------------------------------------------ construction
    @classmethod
    def parse(cls, text: str | "ClassMap" | Sequence) -> "ClassMap":
        """``"2,3+4+5,6"``, ``"ground=2,vegetation=3+4+5:5,building=6"``, a list
        like ``[2, [3, 4, 5], 6]``, or a ClassMap (returned unchanged)."""
        if isinstance(text, ClassMap):
            return text
        if not isinstance(text, str):
            items = []
            for g in text:
                items.append("+".join(str(int(c)) for c in (g if isinstance(g, (list, tuple)) else [g])))
            text = ",".join(items)
        groups, codes, names = [], [], []
        for raw in text.split(","):
            item = raw.strip()
            if not item:
                continue
            m = _ITEM.match(item)
            if not m:
                raise LidarfxError(
                    f"bad class item {item!r}: expected codes joined by '+', e.g. 2,3+4+5,6 "
                    "or ground=2,vegetation=3+4+5,building=6"
                )
            g = tuple(int(c) for c in m.group("codes").replace(" ", "").split("+"))
            out = int(m.group("out")) if m.group("out") is not None else max(g)
            if out not in g:
                raise LidarfxError(f"output code {out} of {item!r} is not one of its classes")
            groups.append(g)
            codes.append(out)
            names.append(m.group("name") or _default_name(g))
        if len(groups) < 2:
            raise LidarfxError(f"a classifier needs at least two classes, got {text!r}")
        return cls(tuple(groups), tuple(codes), tuple(names))

    @classmethod
    def from_codes(cls, codes: Iterable[int], ignore: Iterable[int] = DEFAULT_IGNORE) -> "ClassMap":
        """One output class per code found in the data, minus ``ignore``."""
        ign = set(int(c) for c in ignore)
        keep = sorted(set(int(c) for c in codes) - ign)
        if len(keep) < 2:
            raise LidarfxError(
                f"the training data holds fewer than two usable classes ({keep}); "
                f"ignored: {sorted(ign)}; give --classes"
            )
        return cls(tuple((c,) for c in keep), tuple(keep), tuple(_default_name((c,)) for c in keep))

    def without(self, ignore: Iterable[int]) -> "ClassMap":
        """A copy with the source codes in ``ignore`` removed (empty groups dropped)."""
        ign = set(int(c) for c in ignore)
        groups, codes, names = [], [], []
        for g, c, n in zip(self.groups, self.codes, self.names):
            g2 = tuple(x for x in g if x not in ign)
            if g2:
                groups.append(g2)
                codes.append(c if c in g2 else max(g2))
                names.append(_default_name(g2) if n == _default_name(g) else n)  # a given name stays
        return ClassMap(tuple(groups), tuple(codes), tuple(names))

    # ------------------------------------------------------------------- use
    def __len__(self) -> int:
        return len(self.groups)

    @property
    def source_codes(self) -> list[int]:
        return sorted(c for g in self.groups for c in g)

    def lookup(self) -> np.ndarray:
        """256-entry table: source code → class index (−1 = ignored)."""
        table = np.full(256, -1, dtype=np.int16)
        for i, g in enumerate(self.groups):
            table[list(g)] = i
        return table

    def index_of(self, classification: np.ndarray) -> np.ndarray:
        """Class index (0..k−1) of every point, −1 where the code is ignored."""
        cls = np.asarray(classification)
        if cls.size and (cls.min() < 0 or cls.max() > 255):
            raise LidarfxError("classification codes must be 0..255")
        return self.lookup()[cls.astype(np.int64)]

    def code_of(self, index: np.ndarray) -> np.ndarray:
        """Output code of class indices."""
        return np.asarray(self.codes, dtype=np.int64)[np.asarray(index, dtype=np.int64)]

    def label(self, i: int) -> str:
        return f"{self.names[i]} ({'+'.join(str(c) for c in self.groups[i])})"

    def spec(self) -> str:
        """The map as text (parses back to an equal ClassMap)."""
        out = []
        for g, c, n in zip(self.groups, self.codes, self.names):
            item = "+".join(str(x) for x in g)
            if c != max(g):
                item += f":{c}"
            out.append(f"{n}={item}")
        return ",".join(out)

    def to_dict(self) -> dict:
        return {"groups": [list(g) for g in self.groups], "codes": list(self.codes), "names": list(self.names)}

    @classmethod
    def from_dict(cls, d: dict) -> "ClassMap":
        return cls(tuple(tuple(int(c) for c in g) for g in d["groups"]), tuple(int(c) for c in d["codes"]),
                   tuple(str(n) for n in d["names"]))


def _default_name(group: tuple[int, ...]) -> str:
    if set(group) == {3, 4, 5}:
        return "vegetation"
    if len(group) == 1:
        return ASPRS_NAMES.get(group[0], f"class {group[0]}")
    return "/".join(ASPRS_NAMES.get(c, f"class {c}") for c in group)
