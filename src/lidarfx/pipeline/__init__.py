"""Pipelines: several lidarfx steps run in one process on the same in-memory cloud
(docs/pipelines.md).

>>> from lidarfx import Pipeline
>>> p = Pipeline([{"type": "read", "path": "in.laz"}, {"type": "ground", "hag": True},
...               {"type": "features", "radius": 1.0}, {"type": "classify", "model": "default"},
...               {"type": "write", "path": "out.laz"}])                        # doctest: +SKIP
>>> cloud = p.run()                                                           # doctest: +SKIP
>>> Pipeline.from_json("pipeline.json").run()                                 # doctest: +SKIP

A pipeline is a list of steps, each an object with a ``type`` (a name of the fixed registry
:data:`STEPS`) and the options of the command it stands for, named as the command's long
options (``edge-step`` or ``edge_step``).  Everything is checked before the first step runs:
the structure, every key and value (with the library's own checks), the input files, the
models and references, and every output (format, folder, not an input, not written twice, not
an existing file unless overwriting is allowed).  Nothing in a pipeline is executed as code:
the step type picks an entry of the registry, values are numbers, texts, lists and paths, and
``select`` expressions go to lidarfx's own parser.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from ..errors import LidarfxError
from .spec import Key, Step, shown, suggestion
from .steps import STEPS, Context, step_of

__all__ = ["Pipeline", "STEPS", "Key", "Step", "load_json", "steps_markdown"]

MAX_FILE_BYTES = 1 << 20
"""Largest pipeline file read (a pipeline is a few kB)."""
MAX_STEPS = 1000
MAX_DEPTH = 8
"""Deepest nesting of a pipeline document (document, list of steps, step, list value)."""


class _Object(dict):
    """A JSON object that remembers the keys it was given twice."""

    duplicates: tuple = ()


def _object(pairs: list[tuple[str, Any]]) -> _Object:
    obj = _Object()
    dups = []
    for k, v in pairs:
        if k in obj:
            dups.append(k)
        obj[k] = v
    obj.duplicates = tuple(dups)
    return obj


class _Constant(ValueError):
    pass


def _no_constant(name: str):
    raise _Constant(name)


def _depth(value: Any) -> int:
    """Nesting depth of a parsed JSON value (iterative: no recursion limit)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, (list, dict)):
            deepest = max(deepest, d)
            if d > MAX_DEPTH:
                return d
            stack += [(x, d + 1) for x in (v.values() if isinstance(v, dict) else v)]
    return deepest


def load_json(path: str | os.PathLike) -> Any:
    """The parsed pipeline file at ``path``; a one-line :class:`LidarfxError` for a missing file, a
    file that is not UTF-8 JSON (YAML included), ``NaN``/``Infinity``, more than 1 MiB or
    deeper than :data:`MAX_DEPTH` levels."""
    p = Path(path)
    if not p.exists():
        raise LidarfxError(f"pipeline file not found: {p}")
    if not p.is_file():
        raise LidarfxError(f"{p} is not a file")
    if p.suffix.lower() in (".yaml", ".yml"):
        raise LidarfxError(f"{p}: pipelines are JSON files (YAML is not read); see docs/pipelines.md")
    if p.stat().st_size > MAX_FILE_BYTES:
        raise LidarfxError(f"{p}: {p.stat().st_size:,} bytes is not a pipeline (at most {MAX_FILE_BYTES:,})")
    try:
        text = p.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise LidarfxError(f"{p}: not a pipeline: not UTF-8 text (pipelines are JSON)") from None
    try:
        data = json.loads(text, object_pairs_hook=_object, parse_constant=_no_constant)
    except _Constant as exc:
        raise LidarfxError(f"{p}: {exc} is not a JSON number; give a finite number") from None
    except json.JSONDecodeError as exc:
        raise LidarfxError(f"{p}: not JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise LidarfxError(f"{p}: nested too deeply to be a pipeline") from None
    except ValueError:  # an integer of more than 4300 digits
        raise LidarfxError(f"{p}: not a pipeline: a number with too many digits") from None
    if _depth(data) > MAX_DEPTH:
        raise LidarfxError(f"{p}: nested too deeply to be a pipeline (more than {MAX_DEPTH} levels)")
    return data


def _step_list(data: Any) -> list:
    """The list of steps of a pipeline document: a list, or ``{"pipeline": [...]}`` (with an
    optional ``description``)."""
    if isinstance(data, dict):
        if getattr(data, "duplicates", ()):
            raise LidarfxError(f"key {data.duplicates[0]!r} given twice")
        unknown = [k for k in data if k not in ("pipeline", "description")]
        if unknown:
            raise LidarfxError(f"unknown key {shown(unknown[0])} at the top; a pipeline is "
                               "{\"pipeline\": [steps]} (with an optional \"description\") or a list of steps")
        if "pipeline" not in data:
            raise LidarfxError("no \"pipeline\": a pipeline is {\"pipeline\": [steps]} or a list of steps")
        if not isinstance(data.get("description", ""), str):
            raise LidarfxError("\"description\" must be a text")
        data = data["pipeline"]
    if isinstance(data, tuple):
        data = list(data)
    if not isinstance(data, list):
        raise LidarfxError(f"a pipeline is a list of steps, got {shown(data)}")
    if not data:
        raise LidarfxError("the pipeline has no steps")
    if len(data) > MAX_STEPS:
        raise LidarfxError(f"{len(data):,} steps is more than a pipeline holds (at most {MAX_STEPS})")
    return data


def _step_names() -> str:
    return ", ".join(STEPS)


def _parse_step(i: int, n: int, item: Any) -> tuple[Step, dict]:
    """Step ``i`` (1-based) of ``n``: its registry entry and its complete options, checked."""
    if isinstance(item, str):  # PDAL's shorthand: a file name is the reader (first) or the writer (last)
        if i == 1:
            item = {"type": "read", "path": item}
        elif i == n:
            item = {"type": "write", "path": item}
        else:
            raise LidarfxError(f"step {i}: a file name stands for the read step (first) or the write step (last) "
                               "only; give an object with a \"type\"")
    if not isinstance(item, dict):
        raise LidarfxError(f"step {i}: a step is an object with a \"type\", got {shown(item)}")
    if "type" not in item:
        raise LidarfxError(f"step {i}: no \"type\" (one of {_step_names()})")
    step = step_of(item["type"])
    if step is None:
        t = item["type"]
        hint = suggestion(t.replace("-", "_"), STEPS) if isinstance(t, str) else ""
        raise LidarfxError(f"step {i}: unknown step type {shown(t)}{hint} (steps: {_step_names()})")
    where = f"step {i} ({step.name})"
    if getattr(item, "duplicates", ()):
        raise LidarfxError(f"{where}: key {item.duplicates[0]!r} given twice")
    opts: dict[str, Any] = {}
    given: dict[str, str] = {}
    for raw, value in item.items():
        if raw == "type":
            continue
        key = step.key(raw.replace("-", "_")) if isinstance(raw, str) else None
        if key is None:
            names = [k.name for k in step.keys]
            hint = suggestion(str(raw).replace("-", "_"), names)
            raise LidarfxError(f"{where}: unknown key {shown(raw)}{hint}"
                               + ("" if hint else f" (keys: {', '.join(names)})"))
        if key.name in given:
            raise LidarfxError(f"{where}: key {key.name!r} given twice (as {given[key.name]!r} and {raw!r})")
        given[key.name] = raw
        if isinstance(value, tuple):
            value = list(value)
        try:
            opts[key.name] = key.coerce(value)
        except ValueError as exc:
            hint = exc.args[1] if len(exc.args) > 1 else ""
            raise LidarfxError(f"{where}: {key.name} {exc.args[0]}, got {shown(value)}{hint}") from None
    for key in step.keys:
        if key.name not in opts:
            if key.required:
                raise LidarfxError(f"{where}: missing key {key.name!r} ({key.help})")
            opts[key.name] = list(key.default) if isinstance(key.default, list) else key.default
    if step.check is not None:
        try:
            step.check(opts)
        except LidarfxError as exc:
            raise LidarfxError(f"{where}: {exc}") from None
    return step, opts


def _kind_of(item: Any, j: int, n: int) -> str | None:
    if isinstance(item, str):
        return "read" if j == 0 else "write" if j == n - 1 else None
    step = step_of(item.get("type")) if isinstance(item, dict) else None
    return step.name if step is not None else None


def _replace_path(steps: list, kind: str, value: str, name: str) -> list:
    """``steps`` with the path of the first read step / the last write step replaced by ``value``."""
    found = [j for j, s in enumerate(steps) if _kind_of(s, j, len(steps)) == kind]
    if not found:
        raise LidarfxError(f"{name}: --{'input' if kind == 'read' else 'output'} given, but the pipeline has no "
                           f"{kind} step")
    j = found[0] if kind == "read" else found[-1]
    if isinstance(steps[j], dict):
        item = _Object(steps[j])
        item.duplicates = getattr(steps[j], "duplicates", ())
        item["path"] = value
        steps[j] = item
    else:
        steps[j] = value
    return steps


def _same(a: str, b: str) -> bool:
    pa, pb = Path(a), Path(b)
    if pa.resolve() == pb.resolve():
        return True
    try:
        return pa.exists() and pb.exists() and os.path.samefile(pa, pb)
    except OSError:
        return False


class Pipeline:
    """Steps run one after the other on one in-memory cloud (docs/pipelines.md).

    ``steps``: a list of step objects (dicts with a ``type`` and options, as in a pipeline
    file) or ``{"pipeline": [...]}``.  Every step, key and value is checked here, before any
    work (a one-line :class:`LidarfxError` naming the step and key); the files are checked
    by :meth:`check`, which :meth:`run` calls first.  ``name`` prefixes the messages (the
    pipeline file's path for :meth:`from_json`).
    """

    def __init__(self, steps: Sequence[Any] | dict, *, name: str = "pipeline") -> None:
        self.name = str(name)
        try:
            data = _step_list(steps)
            self.steps: list[tuple[Step, dict]] = [_parse_step(i, len(data), item) for i, item in enumerate(data, 1)]
            for i, (step, _) in enumerate(self.steps[1:], 2):
                if step.kind == "read":
                    raise LidarfxError(f"step {i} (read): only the first step reads; a pipeline works on one cloud")
        except LidarfxError as exc:
            raise LidarfxError(f"{self.name}: {exc}") from None
        self.summary: dict | None = None

    @classmethod
    def from_json(cls, path: str | os.PathLike, *, input: str | None = None, output: str | None = None) -> "Pipeline":
        """The pipeline of a JSON file (docs/pipelines.md).  It must start with a read step and
        write something.  ``input`` / ``output`` replace the path of the read step and of the last
        write step."""
        data = load_json(path)
        name = str(path)
        try:
            steps = _step_list(data)
        except LidarfxError as exc:
            raise LidarfxError(f"{name}: {exc}") from None
        for value, kind in ((input, "read"), (output, "write")):
            if value is not None:
                steps = _replace_path(list(steps), kind, value, name)
        pipe = cls(steps, name=name)
        pipe.require_read()
        if not pipe.outputs():
            raise LidarfxError(f"{name}: the pipeline writes nothing; end it with a write step "
                               "({\"type\": \"write\", \"path\": \"out.laz\"}) or a product step")
        return pipe

    # ------------------------------------------------------------------ checks
    def require_read(self) -> None:
        if self.steps[0][0].kind != "read":
            raise LidarfxError(f"{self.name}: step 1 is {self.steps[0][0].name}: a pipeline starts with a read step "
                               "({\"type\": \"read\", \"path\": \"in.laz\"})")

    def outputs(self) -> list[tuple[int, str, str]]:
        """``(step, path, what)`` of every file and folder the pipeline writes."""
        return [(i, p, what) for i, (s, o) in enumerate(self.steps, 1) for p, what in s.output_paths(o)]

    def inputs(self) -> list[tuple[int, str]]:
        """``(step, path)`` of every file the pipeline reads."""
        return [(i, p) for i, (s, o) in enumerate(self.steps, 1) for p in s.input_paths(o)]

    def check(self, cloud_given: bool = False, *, chunked: bool = False) -> list[Any]:
        """The checks that touch files, before any work: the input files exist and can be read
        (models and references are loaded), and every output has a known format, an existing
        folder, is no input, is written once and (unless overwriting is allowed,
        :data:`lidarfx._atomic.OVERWRITE`) does not exist.  Returns what the steps loaded.
        ``chunked``: the checks of :meth:`run_chunked` (the read path may be a folder of tiles or
        a pattern, the write path a folder; steps a chunk cannot run are refused)."""
        from .. import io
        from .._atomic import check_new_folder, check_output_folder

        if chunked:
            from .chunked import check_chunkable

            try:
                check_chunkable(self)
            except LidarfxError as exc:
                raise LidarfxError(f"{self.name}: {exc}") from None
        if cloud_given and self.steps[0][0].kind == "read":
            raise LidarfxError(f"{self.name}: give run() a cloud or start with a read step, not both")
        if not cloud_given:
            self.require_read()

        def where(i: int) -> str:
            return f"{self.name}: step {i} ({self.steps[i - 1][0].name})"

        ins = self.inputs()
        for i, p in ins:
            try:
                if self.steps[i - 1][0].kind == "read" and chunked:
                    from ..tiles import open_catalog
                    from ..tiles.catalog import inputs_of

                    if self.steps[0][1]["columns"]:
                        raise LidarfxError("in chunks the input is LAS / LAZ; a column spec does not apply")
                    open_catalog(inputs_of(p))  # LAS / LAZ files, a folder of tiles or a pattern
                elif self.steps[i - 1][0].kind == "read":
                    if self.steps[0][1]["columns"] and not io.accepts_columns(p):
                        raise LidarfxError(f"{p}: a column spec applies only to text and .npy files")
                    io.input_format(p)
                elif not Path(p).is_file():
                    raise LidarfxError(f"file not found: {p}" if not Path(p).exists() else f"{p} is not a file")
            except LidarfxError as exc:
                raise LidarfxError(f"{where(i)}: {exc}") from None
        seen: list[tuple[int, str]] = []
        for i, p, what in self.outputs():
            try:
                for j, q in ins:
                    if _same(p, q):
                        raise LidarfxError(f"output {p} is an input of step {j}; choose another output path")
                for j, q in seen:
                    if _same(p, q):
                        raise LidarfxError(f"output {p} is written by step {j} too; give each output its own path")
                if what == "folder" or (what == "cloud" and chunked and not Path(p).suffix):
                    # a product's folder, or in chunks one output file per input tile
                    out = Path(p)
                    if out.exists() and not out.is_dir():
                        raise LidarfxError(f"{out} exists and is not a folder")
                    if not out.parent.is_dir() and str(out.parent) not in ("", "."):
                        raise LidarfxError(f"output folder's parent does not exist: {out.parent}")
                    check_new_folder(out)
                elif what == "cloud":
                    io.check_output_path(p)
                    if chunked:
                        from .._atomic import check_new_file

                        check_new_file(Path(p))
                else:
                    check_output_folder(p)
            except LidarfxError as exc:
                raise LidarfxError(f"{where(i)}: {exc}") from None
            seen.append((i, p))
        prepared = []
        for i, (step, o) in enumerate(self.steps, 1):
            try:
                prepared.append(step.prepare(o, self) if step.prepare is not None else None)
            except LidarfxError as exc:
                raise LidarfxError(f"{where(i)}: {exc}") from None
        return prepared

    def run_chunked(self, *, chunk_size: float | None = None, buffer: float | None = None,
                    workers: int | None = None, scheduler: str | None = None, resume: bool = False,
                    work_dir: str | os.PathLike | None = None, progress: bool | None = None,
                    log: Callable[[str], None] | None = None) -> dict:
        """Run the pipeline chunk by chunk on Dask (docs/pipelines.md "In chunks"): the cloud steps
        fused into one task per chunk, the chunks merged into the write step's file (or folder, one
        file per input tile).  Options as :func:`lidarfx.tiles.run_tiled` takes them (metres).
        Steps a chunk cannot run as the whole cloud does are refused first, with the step named.
        Returns the summary (also in :attr:`summary`)."""
        from .chunked import run_chunked

        self.check(chunked=True)
        try:
            self.summary = run_chunked(self, chunk_size=chunk_size, buffer=buffer, workers=workers,
                                       scheduler=scheduler, resume=resume, work_dir=work_dir, progress=progress,
                                       log=log)
        except LidarfxError as exc:
            raise LidarfxError(f"{self.name}: {exc}") from exc
        return self.summary

    def chunk_problem(self) -> str | None:
        """Why the pipeline cannot run in chunks (the one-line reason), or None when it can."""
        from .chunked import check_chunkable

        try:
            check_chunkable(self)
        except LidarfxError as exc:
            return str(exc)
        return None

    # ------------------------------------------------------------------ plan and run
    def plan(self) -> list[dict]:
        """The validated steps: number, type, the command that does the same, every option
        (defaults filled in), inputs and outputs."""
        return [{"step": i, "type": s.name, "command": s.command,
                 "options": {k: "inf" if v == math.inf else v for k, v in o.items()},
                 "inputs": s.input_paths(o), "outputs": [p for p, _ in s.output_paths(o)]}
                for i, (s, o) in enumerate(self.steps, 1)]

    def plan_text(self) -> str:
        """The plan as text, one step a line (the options given or differing from the defaults,
        then the outputs)."""
        lines = []
        width = max(len(s.name) for s, _ in self.steps)
        for i, (s, o) in enumerate(self.steps, 1):
            defaults = {k.name: k.default for k in s.keys}
            opts = " ".join(f"{k}={_value_text(v)}" for k, v in o.items() if v != defaults.get(k))
            lines.append(f"{i:3d}  {s.name:{width}s}  {opts}".rstrip())
        outs = [p for _, p, _ in self.outputs()]
        lines.append(f"outputs: {', '.join(outs) if outs else 'none'}")
        return "\n".join(lines)

    def run(self, cloud=None, *, progress: bool | None = None, log: Callable[[str], None] | None = None):
        """Run every step and return the last cloud.

        ``cloud``: the input cloud when the pipeline does not start with a read step.
        ``progress``: progress bars of the steps (None: on a terminal for long steps; False:
        none).  ``log``: called with one line per finished step (``[2/5] ground: ...``).
        :attr:`summary` then holds the run: points, per-step seconds and results, outputs."""
        if cloud is not None:
            from ..cloud import PointCloud

            if not isinstance(cloud, PointCloud):
                raise LidarfxError(f"{self.name}: run() takes a PointCloud (see lidarfx.read), got {type(cloud).__name__}")
        prepared = self.check(cloud_given=cloud is not None)
        first, opts0 = self.steps[0]
        source = opts0["path"] if first.kind == "read" else \
            str(cloud.meta.get("name") or cloud.meta.get("source") or "cloud")
        n = len(self.steps)
        rows = []
        t_all = time.perf_counter()
        for i, ((step, o), prep) in enumerate(zip(self.steps, prepared), 1):
            t0 = time.perf_counter()
            try:
                cloud, info = step.run(cloud, o, Context(progress=progress, prepared=prep, source=source))
            except LidarfxError as exc:
                raise LidarfxError(f"{self.name}: step {i} ({step.name}): {exc}") from exc
            sec = round(time.perf_counter() - t0, 3)
            note = info.pop("note", "")
            rows.append({"step": i, "type": step.name, **info, "seconds": sec})
            if log is not None:
                log(f"[{i}/{n}] {step.name}: {note} ({sec:.2f} s)")
        self.summary = {"pipeline": self.name, "source": source, "points": len(cloud), "steps": rows,
                        "outputs": [p for _, p, _ in self.outputs()],
                        "seconds": round(time.perf_counter() - t_all, 3)}
        return cloud


def _value_text(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False) if (" " in v or not v) else v
    return json.dumps(v, ensure_ascii=False)


# ---------------------------------------------------------------------- documentation
def _default_text(key: Key) -> str:
    if key.default is None:
        return "required" if key.required else "—"
    return f"`{json.dumps(key.default, ensure_ascii=False)}`"


def steps_markdown() -> str:
    """The step reference of docs/pipelines.md, generated from :data:`STEPS`."""
    kinds = {"read": "reads the cloud", "cloud": "cloud → cloud", "product": "writes files, passes the cloud on",
             "write": "writes the cloud, passes it on"}
    out = ["| step | what it does | kind | command |", "|---|---|---|---|"]
    for s in STEPS.values():
        also = f" (also `{'`, `'.join(s.aliases)}`)" if s.aliases else ""
        out.append(f"| [`{s.name}`](#{s.name}){also} | {s.help} | {kinds[s.kind]} | `{s.command}` |")
    for s in STEPS.values():
        out += ["", f"### {s.name}", "",
                f"{s.help[0].upper() + s.help[1:]}. Runs `{s.function}`, as `{s.command}` does."]
        if s.key_aliases:
            out[-1] += " " + "; ".join(f"`{a}` is `{k}`" for a, k in s.key_aliases.items()) + "."
        out += ["", "| key | type | default | meaning |", "|---|---|---|---|"]
        for k in s.keys:
            out.append(f"| `{k.name}` | {k.type_text} | {_default_text(k)} | {k.help} |")
    return "\n".join(out) + "\n"

