"""The pieces of the step registry: :class:`Key` (one option of a step, its type and the check of
a value from a pipeline file) and :class:`Step` (a step type: its keys, the library call it runs,
its checks and its outputs).  Nothing here runs code named by a pipeline: a value is only ever
compared, converted to a number, a list of numbers or a path, or handed to a lidarfx parser.
"""
from __future__ import annotations

import difflib
import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable


MAX_TEXT = 4096
"""Longest text value (a path, an expression, a feature list)."""
MAX_LIST = 256
"""Longest list value (radii, class codes, load cases)."""

KINDS = {
    "number": "number",
    "length": "number, m",
    "int": "integer",
    "bool": "true / false",
    "text": "text",
    "choice": "one of",
    "lengths": "number or list of numbers, m",
    "numbers": "list of numbers or \"a,b,c\"",
    "codes": "list of class codes or \"2,9\"",
    "texts": "text or list of texts",
    "input": "path of an existing file",
    "output": "path of a new file",
    "outdir": "path of a new or empty folder",
    "csv": "true or a path",
    "size": "\"WxH\" or [W, H]",
}
"""The value types of keys, as the documentation names them."""


def shown(value: Any, limit: int = 60) -> str:
    """A value for an error message: JSON, cut to ``limit`` characters."""
    try:
        text = json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError, RecursionError):
        text = type(value).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def suggestion(word: str, known) -> str:
    """"; did you mean 'x'?" for the closest of ``known``, else ""."""
    lower = {str(k).lower(): k for k in known}
    close = difflib.get_close_matches(str(word).lower(), list(lower), n=1, cutoff=0.6)
    return f"; did you mean {lower[close[0]]!r}?" if close else ""


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not _is_bool(v)


def _is_int(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not _is_bool(v)


def _is_bool(v: Any) -> bool:
    return isinstance(v, bool) or type(v).__name__ == "bool_"


def _number(v: Any) -> float:
    if not _is_number(v) or not math.isfinite(float(v)):
        raise ValueError("must be a finite number")
    return float(v)


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


@dataclass(frozen=True)
class Key:
    """One key of a step: ``name`` (underscores; a file may write dashes), ``kind`` (one of
    :data:`KINDS`), its ``default`` (None: not given, the function's own default), ``help`` and
    ``choices``, ``count`` (how many numbers a ``numbers`` key takes: 3, or (2, 3)),
    ``suffixes`` (the extensions an ``output`` key takes; empty: any format lidarfx writes) and
    ``required``."""

    name: str
    kind: str
    default: Any = None
    help: str = ""
    choices: tuple = ()
    count: tuple = ()
    suffixes: tuple = ()
    required: bool = False

    def coerce(self, value: Any) -> Any:
        """The value as the function takes it; otherwise ValueError(reason[, hint]): "must be a
        number", "; did you mean 'sphere'?"."""
        k = self.kind
        if k in ("number", "length"):
            if value == "inf" and "inf" in self.choices:
                return math.inf
            return _number(value)
        if k == "int":
            if not _is_int(value):
                raise ValueError("must be a whole number")
            return int(value)
        if k == "bool":
            if not _is_bool(value):
                raise ValueError("must be true or false")
            return bool(value)
        if k == "choice":
            if not isinstance(value, str) or value not in self.choices:
                raise ValueError(f"must be one of {', '.join(self.choices)}",
                                 suggestion(value, self.choices) if isinstance(value, str) else "")
            return value
        if k == "lengths":
            items = value if isinstance(value, list) else [value]
            if not items or len(items) > MAX_LIST:
                raise ValueError(f"must be a number or a list of 1 to {MAX_LIST} numbers")
            try:
                return [_number(v) for v in items]
            except ValueError:
                raise ValueError("must be a number or a list of numbers") from None
        if k == "numbers":
            items = value
            if isinstance(value, str) and len(value) <= MAX_TEXT:
                try:
                    items = [float(t) for t in value.replace(" ", "").split(",")]
                except ValueError:
                    items = None
            counts = " or ".join(map(str, self.count))
            if not isinstance(items, list) or len(items) not in self.count:
                raise ValueError(f"must be {counts} numbers, as a list or \"a,b,c\"")
            try:
                return [_number(v) for v in items]
            except ValueError:
                raise ValueError(f"must be {counts} finite numbers") from None
        if k == "codes":
            items = value
            if isinstance(value, str) and len(value) <= MAX_TEXT:
                if value.strip().lower() in ("none", ""):
                    return []
                if value.strip().lower() == "all" and "all" in self.choices:
                    return "all"
                try:
                    items = [int(t) for t in _split(value)]
                except ValueError:
                    items = None
            if not isinstance(items, list) or len(items) > MAX_LIST or \
                    not all(_is_int(c) for c in items):
                raise ValueError("must be class codes: a list of whole numbers, \"2,9\" or \"none\"")
            return [int(c) for c in items]
        if k == "texts":
            items = value if isinstance(value, list) else [value]
            if len(items) > MAX_LIST or not all(isinstance(t, str) and len(t) <= MAX_TEXT for t in items):
                raise ValueError("must be a text or a list of texts")
            return list(items)
        if k == "csv":
            if value is True or value is False:
                return value
            return _text(value)
        if k == "size":
            if isinstance(value, list) and len(value) == 2 and all(_is_int(v) for v in value):
                return f"{value[0]}x{value[1]}"
            if isinstance(value, str) and len(value) <= 40:
                return value
            raise ValueError("must be \"WIDTHxHEIGHT\" or [WIDTH, HEIGHT] in pixels")
        # text, input, output, outdir
        text = _text(value)
        if k in ("input", "output", "outdir") and not text.strip():
            raise ValueError("must be a path")
        if k == "output" and self.suffixes and Path(text).suffix.lower() not in self.suffixes:
            raise ValueError(f"must be a path ending in {' or '.join(self.suffixes)}")
        return text

    @property
    def type_text(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(f"`{c}`" for c in self.choices)
        if self.kind == "numbers":
            return f"{' or '.join(map(str, self.count))} numbers"
        if self.kind == "output" and self.suffixes:
            return "path of a new " + " / ".join(self.suffixes) + " file"
        return KINDS[self.kind]


def _text(value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError("must be a text")
    if len(value) > MAX_TEXT:
        raise ValueError(f"is longer than {MAX_TEXT} characters")
    if "\x00" in value:
        raise ValueError("holds a NUL character")
    return value


@dataclass(frozen=True)
class Step:
    """A step type of the registry.

    ``kind``: ``read`` (makes the cloud), ``cloud`` (cloud in, cloud out), ``product`` (writes
    files from the cloud and passes it on unchanged) or ``write``.  ``run(cloud, options, job)``
    returns ``(cloud, info)``: the cloud for the next step and a dict for the summary
    (``note`` is the text of the progress line).  ``check(options)`` runs the library's own
    option checks (no file is touched); ``prepare(options, job)`` the checks that read files
    (a model, references), before any step runs, and keeps what they load in ``job``;
    ``outputs(options)`` lists ``(path, what)`` of every file or folder the step writes.
    ``command`` is the command line that does the same, ``function`` the library function."""

    name: str
    kind: str
    help: str
    command: str
    function: str
    keys: tuple[Key, ...]
    run: Callable[..., tuple[Any, dict]]
    check: Callable[[dict], None] | None = None
    prepare: Callable[[dict, Any], None] | None = None
    outputs: Callable[[dict], list[tuple[str, str]]] | None = None
    inputs: Callable[[dict], list[str]] | None = None
    aliases: tuple[str, ...] = ()
    key_aliases: dict = field(default_factory=dict)

    def key(self, name: str) -> Key | None:
        name = self.key_aliases.get(name, name)
        for k in self.keys:
            if k.name == name:
                return k
        return None

    def output_paths(self, options: dict) -> list[tuple[str, str]]:
        """``(path, what)`` of every file and folder this step writes with ``options``; ``what``
        is ``cloud`` (a point-cloud file: its format from the extension), ``file`` or ``folder``."""
        if self.outputs is not None:
            return self.outputs(options)
        out = []
        for k in self.keys:
            if k.kind in ("output", "outdir") and options.get(k.name):
                out.append((options[k.name], "folder" if k.kind == "outdir" else "file" if k.suffixes else "cloud"))
        return out

    def input_paths(self, options: dict) -> list[str]:
        """The files this step reads besides the cloud (and, for ``read``, the cloud's file)."""
        if self.inputs is not None:
            return self.inputs(options)
        return [options[k.name] for k in self.keys if k.kind == "input" and options.get(k.name)]
