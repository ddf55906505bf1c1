"""Hostile files: mutated copies of the real data through every command that reads a cloud.

The corpus, the command lines and the worker processes live in ``tests/fuzzcorpus.py``; the
contract per run is :func:`fuzzcorpus.check_run` (exit 0 or 2, one ``lidarfx: error:`` line,
never a traceback, no output left after an error, the input untouched, within the time limit,
no worker death under the 3 GB address-space limit).  ``docs/reliability.md`` ("Hostile files")
gives the figures.

The default run is one round (seed 0): 300 mutants (every one of the 230 mutation operators at
least once) and 3,840 runs, 3 to 4 minutes on two cores.  ``LIDARFX_FUZZ_BUDGET=N`` runs N
rounds (seeds 0 .. N-1, other mutants each round); ``LIDARFX_FUZZ_WORKERS`` sets the worker
processes (default 2); ``LIDARFX_FUZZ_RECORD=FILE`` writes every run's result as JSON.
``python tools/fuzz_cli.py mutants --rounds N`` is the same by hand.
"""
from __future__ import annotations

import collections
import hashlib
import json
import os
import time
from pathlib import Path

import pytest

import fuzzcorpus as fc


def _real_data_or_skip() -> None:
    if not any(fc.REAL.glob("*.la[sz]")):
        pytest.skip(f"real data not found: {fc.REAL} (shared/data/real beside the repository, see its SOURCES.md)")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    _real_data_or_skip()
    root = tmp_path_factory.mktemp("fuzz")
    sources = fc.cut_sources(root / "sources")
    rounds = int(os.environ.get("LIDARFX_FUZZ_BUDGET", "1"))
    mutants = [m for seed in range(rounds) for m in fc.build_corpus(sources, root / "mutants", seed=seed)]
    return root, sources, mutants


def _digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# ----------------------------------------------------------------------------- the corpus


def test_the_cuts_are_valid_small_copies_of_the_real_files(corpus):
    import laspy

    from lidarfx import read

    _, sources, _ = corpus
    las = [s for s in sources if s.family == "las"]
    assert len(las) >= 30 and {s.family for s in sources} == {"las", "ply", "text"}
    for s in sources:
        cloud = read(s.path)
        assert len(cloud) == fc.CUT_POINTS, s.name
        if s.family != "las":
            continue
        with laspy.open(fc.REAL / s.origin) as original, laspy.open(s.path) as cut:
            a, b = original.header, cut.header
            assert (b.version.major, b.version.minor) == (a.version.major, a.version.minor), s.name
            assert b.point_format.id == a.point_format.id, s.name
            kept = [v.user_id for v in a.vlrs if v.user_id != "laszip encoded"]
            assert [v.user_id for v in b.vlrs if v.user_id != "laszip encoded"][: len(kept)] == kept, s.name
            if not s.name.endswith("_eb.las") and not s.name.endswith("_eb.laz"):
                assert list(b.point_format.extra_dimension_names) == list(a.point_format.extra_dimension_names)
    evlr = [s for s in las if "_evlr" in s.name]
    assert evlr and all(read(s.path).header.evlrs for s in evlr)
    assert any(read(s.path).header.point_format.extra_dimension_names for s in las if "_eb" in s.name)


def test_the_mutants_are_many_of_every_kind_and_reproducible(corpus, tmp_path):
    _, sources, mutants = corpus
    first = [m for m in mutants if m.seed == 0]
    kinds = collections.Counter(m.kind for m in first)
    assert len(first) >= 200 and set(kinds) == set(fc.KINDS) and min(kinds.values()) >= fc.PER_COMMAND
    for kind in fc.KINDS:  # one round applies every mutation operator of every kind
        assert {m.what for m in first if m.kind == kind} == {op[0] for op, _ in fc._ops_for(kind)}, kind
    again = fc.build_corpus(sources, tmp_path / "again", seed=0)
    assert [(m.name, m.what, _digest(m.path)) for m in again] == [(m.name, m.what, _digest(m.path)) for m in first]
    other = fc.build_corpus(sources, tmp_path / "other", seed=1)
    assert [_digest(m.path) for m in other] != [_digest(m.path) for m in first]
    by_name = {s.name: s for s in sources}
    changed = [m for m in first if _digest(m.path) != _digest(by_name[m.source].path) or Path(m.path).suffix !=
               Path(by_name[m.source].path).suffix]
    # a mutant differs from its source (bytes or name) unless its operator sets what the source
    # already holds (e.g. 'legacy 0, 1.4 count n' on a LAS 1.4 file written that way): a few at most
    assert len(first) - len(changed) <= len(first) // 100, [m.name for m in first if m not in changed]


def test_every_command_sees_every_kind(corpus):
    _, _, mutants = corpus
    cases = fc.plan(mutants)
    assert sorted(c.i for c in cases) == list(range(len(cases)))
    seen = collections.defaultdict(set)
    for c in cases:
        seen[c.command, c.kind].add(c.mutant)
    for command in fc.COMMANDS:
        for kind in fc.KINDS:
            every = {m.name for m in mutants if m.kind == kind}
            if command in fc.READERS:
                assert seen[command, kind] == every, (command, kind)
            else:
                assert len(seen[command, kind]) >= fc.PER_COMMAND, (command, kind)


# ----------------------------------------------------------------------------- the harness


def test_the_contract_check():
    ok = fc.check_run
    assert ok(0, "", [], False) == []
    assert ok(0, "lidarfx: warning: 3 of 9 points have a NaN x, y or z and are left out\n", [], False) == []
    assert ok(2, "lidarfx: warning: w\nlidarfx: error: bad file\n", [], False) == []
    assert ok(2, "lidarfx: error: bad file\n", ["o.laz"], False) == ["left behind after an error: ['o.laz']"]
    assert ok(2, "lidarfx: error: a\nlidarfx: error: b\n", [], False) == ["2 error lines"]
    assert ok(2, "", [], False) == ["0 error lines"]
    assert ok(1, "lidarfx: error: out of memory\n", [], False) == ["exit code 1"]
    assert ok(0, "", [], True) == ["the input or its folder changed"]
    tb = ok(1, "Traceback (most recent call last):\n  File x\nValueError: boom\n", [], False)
    assert tb[0] == "traceback: ValueError: boom" and "exit code 1" in tb
    assert ok(0, "x.py:3: RuntimeWarning: overflow\n  y = a * b\n", [], False) == [
        "stray stderr: x.py:3: RuntimeWarning: overflow"]
    assert ok(0, "lidarfx: error: said but went on\n", [], False) == ["an error line with exit code 0"]


def test_a_dead_a_hung_and_a_buggy_run_are_reported_and_the_rest_still_runs(tmp_path):
    import laspy
    import numpy as np

    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.x, las.y, las.z = np.arange(50.0), np.arange(50.0) % 7, np.zeros(50)
    las.write(tmp_path / "ok.las")
    good = str(tmp_path / "ok.las")
    argvs = [["info", good], ["__crash__"], ["info", good], ["__hang__"], ["convert", good, "{OUT}/o.ply"],
             ["__raise__"], ["convert", good, "{OUT}/o.laz"], ["info", str(tmp_path / "missing.las")]]
    cases = [fc.Case(i, a[0], "self", "ok.las", "", a, good) for i, a in enumerate(argvs)]
    t0 = time.monotonic()
    out = fc.run_cases(cases, tmp_path / "run", workers=1, case_seconds=3, grace=2)
    assert time.monotonic() - t0 < 120
    res = out.results
    assert sorted(res) == list(range(len(argvs)))
    assert [res[i]["rc"] for i in (0, 2, 4, 6)] == [0, 0, 0, 0]
    assert res[1]["problems"] == ["worker died (exit 3)"]
    assert res[3]["problems"] == ["no answer in 5 s (worker killed)"]
    assert res[5]["problems"][0] == "traceback: RuntimeError: a bug"
    assert res[7]["rc"] == 2 and res[7]["problems"] == []  # a missing file: one line, exit 2
    assert out.restarts == 2 and len(out.bad()) == 3


# ----------------------------------------------------------------------------- the run


def test_hostile_files_keep_the_contract(corpus, capsys):
    """Every mutant through info and convert, each other command through 30 mutants of every
    kind; the runs in two long-lived workers; every broken contract listed."""
    root, sources, mutants = corpus
    cases = fc.plan(mutants, per_command=fc.PER_COMMAND * len({m.seed for m in mutants}))
    workers = int(os.environ.get("LIDARFX_FUZZ_WORKERS", "2"))
    outcome = fc.run_cases(cases, root / "run", workers=workers, warmup=fc.warmup_argvs(sources))
    text = fc.summary(outcome, cases)
    record = os.environ.get("LIDARFX_FUZZ_RECORD")
    if record:
        Path(record).write_text(json.dumps({"mutants": len(mutants), "runs": len(cases), "seconds": outcome.seconds,
                                            "cases": [c.__dict__ for c in cases], "results": outcome.results},
                                           default=str))
    exits = collections.Counter((cases[i].command, r["rc"]) for i, r in outcome.results.items())
    with capsys.disabled():
        print(f"\nhostile files: {len(mutants)} mutants, {text}")
    assert len(outcome.results) == len(cases)
    assert not outcome.bad(), text
    for command in fc.COMMANDS:  # each command's own work is reached, not only the readers' refusals
        assert exits[command, 0] >= 1, (command, exits)
