"""Fuzz the command line with bad input (run by hand; not part of the test suite).

    python tools/fuzz_cli.py                 # the parts files, options, synth: about 15 minutes on 2 cores
    python tools/fuzz_cli.py files synth     # only some parts: files, options, synth, mutants
    python tools/fuzz_cli.py mutants --rounds 10   # hostile copies of the real data, 10 seeds

The guide's rule for bad input: a one-line error and exit code 2 — never a traceback, a crash,
a half-written output or a modified input.  Three parts check it:

* ``files``: every command on missing, folder, empty, garbage and truncated LAZ files, header-only
  text, NaN coordinates, word columns, and clouds of 0, 1 and 50 identical points;
* ``options``: every numeric option of every command with 0, -1, nan, inf, 1e308 and 1e-300
  (integer options: 0, -1, 10^9 and a 23-digit number);
* ``synth``: every scene parameter of ``lidarfx synth -p KEY=VALUE`` with 0, -1, nan and 1e9;
* ``mutants`` (not in the default set): the hostile-file suite of ``tests/test_reliability_fuzz.py``
  at a larger budget: ``--rounds N`` seeds from ``--first-seed`` (each round 300 mutated copies
  of the real data and 3,840 runs, 3 to 4 minutes on 2 cores), ``--workers``, ``--record
  FILE`` for every run's result as JSON.  It needs the real data (``shared/data/real``).

A run is BAD when it prints a traceback, exits with another code than 0 or 2, leaves output behind
after an error, modifies an input, or runs longer than the time limit (``--timeout``, default 120 s).
Prints the BAD runs and exits 1 if there is any.  Inputs are generated in a temporary folder (a
synthetic labelled town; no data file is needed).
"""
from __future__ import annotations

import argparse
import glob
import hashlib
import inspect
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
if (SRC / "lidarfx").is_dir():
    sys.path.insert(0, str(SRC))

import numpy as np  # noqa: E402  (after the path set-up above)

ENV = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
BAD_FILES = ["missing.laz", "adir", "empty.laz", "garbage.laz", "trunc.laz", "hdr.xyz", "nan.xyz", "words.xyz",
             "zero.las", "one.las", "same.las", "flat.las"]


def _las(path, xyz, cls):
    import laspy

    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales, h.offsets = [0.01] * 3, [0.0, 0.0, 0.0]
    las = laspy.LasData(h)
    if len(xyz):
        las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
        las.classification = cls
        las.return_number = np.ones(len(xyz), np.uint8)
        las.number_of_returns = np.ones(len(xyz), np.uint8)
    las.write(path)


def make_inputs(d: Path) -> None:
    """The bad inputs, a labelled synthetic town (town.laz) and a model trained on it (m.skops)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_objects import _town

    import lidarfx

    town = _town(1, size=40.0, density=10.0)
    n = len(town)
    town["return_number"] = np.ones(n, np.uint8)
    town["number_of_returns"] = np.ones(n, np.uint8)
    lidarfx.write(town, d / "town.laz")
    b = (d / "town.laz").read_bytes()
    (d / "trunc.laz").write_bytes(b[: len(b) // 2])
    (d / "empty.laz").write_bytes(b"")
    (d / "garbage.laz").write_bytes(np.random.default_rng(0).bytes(5000))
    (d / "hdr.xyz").write_text("x y z\n")
    (d / "nan.xyz").write_text("1 2 3\nnan 2 3\n4 5 6\n")
    (d / "words.xyz").write_text("a b c\nd e f\n")
    _las(d / "zero.las", np.zeros((0, 3)), np.zeros(0, np.uint8))
    _las(d / "one.las", np.array([[1.0, 2.0, 3.0]]), np.array([2], np.uint8))
    _las(d / "same.las", np.tile([[1.0, 2.0, 3.0]], (50, 1)), np.full(50, 2, np.uint8))
    rng = np.random.default_rng(0)
    flat = np.column_stack([rng.uniform(0, 10, 500), rng.uniform(0, 10, 500), rng.normal(0, 0.01, 500)])
    _las(d / "flat.las", flat, np.full(500, 2, np.uint8))
    (d / "adir").mkdir()
    r = _run(["classify", "train", "town.laz", "--model", "m.skops", "--classes", "2,5,6", "-f",
              "eigen,height_above_ground", "-r", "1", "-r", "2", "--classifier", "rf", "--n-estimators", "10",
              "--terrain-augment", "0", "-q"], d, 600)
    if r.returncode:
        sys.exit(f"could not train the fuzz model: {r.stderr[-500:]}")


def _run(argv, cwd, timeout):
    return subprocess.run([sys.executable, "-m", "lidarfx", *argv], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=ENV, check=False)


def _hashes(d: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in d.iterdir() if p.is_file()}


def check(argv, d: Path, timeout: float, bad: list) -> None:
    out = d / "out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    before = _hashes(d)
    try:
        r = _run(argv, d, timeout)
    except subprocess.TimeoutExpired:
        bad.append((argv, f"no answer in {timeout:g} s"))
        return
    problems = []
    if "Traceback" in r.stderr:
        problems.append("traceback: " + r.stderr.strip().splitlines()[-1][:160])
    if r.returncode not in (0, 2):
        problems.append(f"exit code {r.returncode}")
    left = [f for f in glob.glob(str(out / "**"), recursive=True) if os.path.isfile(f)]
    if r.returncode != 0 and left:
        problems.append(f"left behind: {[Path(f).name for f in left]}")
    if _hashes(d) != before:
        problems.append("an input changed")
    if problems:
        bad.append((argv, "; ".join(problems)))
    print(("BAD " if problems else "ok  ") + " ".join(argv)[:150], flush=True)


COMMANDS = {
    ("info",): ["{IN}"],
    ("convert",): ["{IN}", "out/o.ply"],
    ("features",): ["{IN}", "out/o.laz", "-r", "1", "-q"],
    ("segment",): ["{IN}", "out/o.laz", "-q"],
    ("select",): ["{IN}", "out/o.laz", "-w", "z > 0", "-q"],
    ("ground",): ["{IN}", "out/o.laz", "--hag", "-q"],
    ("ground-eval",): ["{IN}", "-q"],
    ("dtm",): ["{IN}", "out/o.tif", "-q"],
    ("classify", "predict"): ["{IN}", "out/o.laz", "--model", "m.skops", "-q"],
    ("classify", "train"): ["{IN}", "--model", "out/x.skops", "--classes", "2,5,6", "-q"],
    ("classify", "evaluate"): ["{IN}", "--cv", "2", "--out", "out/ev", "--no-random-folds", "-q"],
    ("eigenclass",): ["{IN}", "out/o.laz", "-r", "1", "-q"],
    ("edges",): ["{IN}", "out/o.geojson", "-r", "1", "--csv", "--dxf", "out/o.dxf", "-q"],
    ("powerlines",): ["{IN}", "out/pl", "--load-case", "temp=80", "-q"],
    ("discontinuities",): ["{IN}", "out/dc", "-q"],
    ("colour",): ["{IN}", "out/o.laz", "--picture", "out/o.png", "-q"],
    ("breaklines",): ["{IN}", "out/o.geojson", "--csv", "--dxf", "out/o.dxf", "--picture", "out/o.png", "-q"],
    ("thin",): ["{IN}", "out/o.laz", "--cell", "0.5", "-q"],
    ("section",): ["{IN}", "out/o.laz", "--from", "0,5", "--to", "10,5", "--width", "1", "--image", "out/o.png", "--by", "z", "-q"],
    ("parts",): ["{IN}", "out/pa", "-q"],
    ("members",): ["{IN}", "out/o.geojson", "--csv", "--dxf", "out/o.dxf", "--picture", "out/o.png", "-q"],
}


def part_files(d, timeout, bad):
    for cmd, rest in COMMANDS.items():
        for f in BAD_FILES:
            check([*cmd, *[a.replace("{IN}", f) for a in rest]], d, timeout, bad)


def _subparsers(parser, prefix=()):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sp in a.choices.items():
                yield from _subparsers(sp, (*prefix, name))
            return
    yield prefix, parser


INT_VALUES = ["0", "-1", "1000000000", "99999999999999999999999"]
"""Values tried on every integer option (session 16 added the huge ones: allocations, hours, tracebacks)."""
FLOAT_VALUES = ["0", "-1", "nan", "inf", "1e308", "1e-300"]
"""Values tried on every float option (1e-300: squares that underflow, grid keys that overflow)."""


def part_options(d, timeout, bad):
    from lidarfx.cli import build_parser

    base = {k: [a.replace("{IN}", "town.laz" if k[0] == "classify" else "flat.las") for a in v]
            for k, v in COMMANDS.items()}
    base[("synth",)] = ["plane", "out/s.laz"]
    for prefix, sp in _subparsers(build_parser()):
        if prefix not in base:
            continue
        for a in sp._actions:
            if a.type not in (int, float) or not a.option_strings:
                continue
            for v in (INT_VALUES if a.type is int else FLOAT_VALUES):
                check([*prefix, *base[prefix], a.option_strings[-1], v], d, timeout, bad)


def part_synth(d, timeout, bad):
    from lidarfx.synth import GENERATORS

    common = {"seed", "density", "noise", "sampling", "rotation", "origin", "radius", "query_point", "classes",
              "scanner", "sets", "arms"}
    for kind, func in GENERATORS.items():
        for p in inspect.signature(func).parameters:
            if p not in common:
                for v in ("0", "-1", "nan", "1e9"):
                    check(["synth", kind, "out/s.laz", "-p", f"{p}={v}"], d, timeout, bad)


def part_mutants(d, timeout, bad, *, rounds=1, first_seed=0, workers=2, record=None):
    """The hostile-file suite (tests/fuzzcorpus.py) over ``rounds`` seeds."""
    import json

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import fuzzcorpus as fc

    sources = fc.cut_sources(d / "sources")
    if not sources:
        sys.exit(f"no real data in {fc.REAL} (see its SOURCES.md)")
    mutants = [m for seed in range(first_seed, first_seed + rounds)
               for m in fc.build_corpus(sources, d / "mutants", seed=seed)]
    cases = fc.plan(mutants, per_command=fc.PER_COMMAND * rounds)
    print(f"{len(mutants)} mutants, {len(cases)} runs", flush=True)
    done = [0]

    def log(r):
        done[0] += 1
        if r["i"] >= 0 and r["problems"]:
            c = cases[r["i"]]
            print(f"BAD  {c.command} on {c.mutant} ({c.kind}: {c.what}): {'; '.join(r['problems'])}", flush=True)
        elif done[0] % 500 == 0:
            print(f"{done[0]} runs", flush=True)

    out = fc.run_cases(cases, d / "run", workers=workers, case_seconds=timeout, warmup=fc.warmup_argvs(sources),
                       log=log)
    print(fc.summary(out, cases).splitlines()[0])
    if record:
        Path(record).write_text(json.dumps({"mutants": len(mutants), "runs": len(cases), "seconds": out.seconds,
                                            "cases": [c.__dict__ for c in cases], "results": out.results}, default=str))
    for r in out.bad():
        c = cases[r["i"]]
        bad.append((c.argv, f"{c.kind}: {c.what}: {'; '.join(r['problems'])}"))


def main() -> int:
    import functools

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("parts", nargs="*", metavar="PART",
                    help="files, options, synth, mutants (default: files, options and synth)")
    ap.add_argument("--timeout", type=float, default=None,
                    help="seconds per run (default 120; mutants: 30)")
    ap.add_argument("--rounds", type=int, default=1, help="mutants: seeds to run (default 1)")
    ap.add_argument("--first-seed", type=int, default=0, help="mutants: the first seed (default 0)")
    ap.add_argument("--workers", type=int, default=2, help="mutants: worker processes (default 2)")
    ap.add_argument("--record", default=None, metavar="FILE", help="mutants: every run's result as JSON")
    args = ap.parse_args()
    parts = args.parts or ["files", "options", "synth"]
    unknown = sorted(set(parts) - {"files", "options", "synth", "mutants"})
    if unknown:
        ap.error(f"unknown part(s) {', '.join(unknown)}; choose from files, options, synth, mutants")
    if args.rounds < 1 or args.workers < 1:
        ap.error("--rounds and --workers must be at least 1")
    mutants = functools.partial(part_mutants, rounds=args.rounds, first_seed=args.first_seed, workers=args.workers,
                                record=args.record)
    bad: list = []
    with tempfile.TemporaryDirectory(prefix="lidarfx-fuzz-") as tmp:
        d = Path(tmp)
        if {"files", "options"} & set(parts):
            make_inputs(d)
        for part in parts:
            timeout = args.timeout or (30.0 if part == "mutants" else 120.0)
            {"files": part_files, "options": part_options, "synth": part_synth,
             "mutants": mutants}[part](d, timeout, bad)
    print(f"\n{len(bad)} bad run(s)")
    for argv, why in bad:
        print(f"  lidarfx {' '.join(argv)}: {why}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
