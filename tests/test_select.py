"""Selection by criteria: the safe expression parser and ``lidarfx select`` (docs/segmentation.md §5, issue 6)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import lidarfx
from lidarfx import LidarfxError, PointCloud
from lidarfx.cli import main
from lidarfx.select import Expression, evaluate, names_in, parse, select

NAN = np.nan


@pytest.fixture()
def cloud() -> PointCloud:
    x = np.arange(6, dtype=float)
    return PointCloud(
        np.c_[x, 10.0 - x, 2.0 * x],
        {
            "segment_id": np.array([-1, 0, 1, 2, 2, 3], np.int32),
            "segment_size": np.array([0, 80, 20, 60, 60, 51], np.int32),
            "planarity": np.array([0.1, 0.6, NAN, 0.9, 0.2, 0.7], np.float32),
            "planarity_r0.50": np.array([0.5, 0.5, 0.5, 0.8, 0.8, 0.8], np.float32),
            "classification": np.array([2, 6, 6, 5, 2, 1], np.uint8),
            "return_number": np.array([1, 1, 2, 1, 2, 3], np.uint8),
            "number_of_returns": np.array([1, 2, 2, 3, 3, 3], np.uint8),
            "withheld": np.array([0, 0, 1, 0, 0, 1], bool),
        },
    )


def ev(cloud, expr) -> list[int]:
    return evaluate(cloud, expr).astype(int).tolist()


# ------------------------------------------------------------------ operators
@pytest.mark.parametrize(
    "expr, want",
    [
        ("x < 2", [1, 1, 0, 0, 0, 0]),
        ("x <= 2", [1, 1, 1, 0, 0, 0]),
        ("x > 3", [0, 0, 0, 0, 1, 1]),
        ("x >= 3", [0, 0, 0, 1, 1, 1]),
        ("x == 3", [0, 0, 0, 1, 0, 0]),
        ("x != 3", [1, 1, 1, 0, 1, 1]),
        ("1 < x <= 3", [0, 0, 1, 1, 0, 0]),  # chained like Python
        ("5 > x > 1 > 0", [0, 0, 1, 1, 1, 0]),
        ("x + 1 == 3", [0, 0, 1, 0, 0, 0]),
        ("x - 1 == 3", [0, 0, 0, 0, 1, 0]),
        ("x * 2 == z", [1, 1, 1, 1, 1, 1]),
        ("z / 4 == 1", [0, 0, 1, 0, 0, 0]),
        ("x % 2 == 1", [0, 1, 0, 1, 0, 1]),
        ("x ** 2 == 9", [0, 0, 0, 1, 0, 0]),
        ("-x == -2", [0, 0, 1, 0, 0, 0]),
        ("+x == 2", [0, 0, 1, 0, 0, 0]),
        ("x > 1 and x < 4", [0, 0, 1, 1, 0, 0]),
        ("x < 1 or x > 4", [1, 0, 0, 0, 0, 1]),
        ("not x > 1", [1, 1, 0, 0, 0, 0]),
        ("classification in [2, 6]", [1, 1, 1, 0, 1, 0]),
        ("classification in (5,)", [0, 0, 0, 1, 0, 0]),
        ("classification not in [2, 6]", [0, 0, 0, 1, 0, 1]),
        ("not classification in [2, 6]", [0, 0, 0, 1, 0, 1]),
        ("segment_id in []", [0, 0, 0, 0, 0, 0]),
        ("withheld", [0, 0, 1, 0, 0, 1]),  # a boolean attribute is a condition
        ("not withheld and x > 0", [0, 1, 0, 1, 1, 0]),
        ("True", [1, 1, 1, 1, 1, 1]),
        ("False or x == 0", [1, 0, 0, 0, 0, 0]),
        ("y == 10 - x", [1, 1, 1, 1, 1, 1]),
        ("2.5e0 < x", [0, 0, 0, 1, 1, 1]),
    ],
)
def test_operators(cloud, expr, want):
    assert ev(cloud, expr) == want


@pytest.mark.parametrize(
    "expr, want",
    [
        ("x == 0 or x == 5 and x == 0", [1, 0, 0, 0, 0, 0]),  # and binds tighter than or
        ("(x == 0 or x == 5) and x == 0", [1, 0, 0, 0, 0, 0]),
        ("(x == 0 or x == 5) and not x == 0", [0, 0, 0, 0, 0, 1]),
        ("not x == 0 or x == 0", [1, 1, 1, 1, 1, 1]),  # not binds tighter than or
        ("not (x == 0 or x == 1)", [0, 0, 1, 1, 1, 1]),
        ("2 + 3 * x == 11", [0, 0, 0, 1, 0, 0]),  # * before +
        ("(2 + 3) * x == 10", [0, 0, 1, 0, 0, 0]),
        ("-x ** 2 == -9", [0, 0, 0, 1, 0, 0]),  # ** before unary minus
        ("2 ** 3 ** 2 == 512 and x == 0", [1, 0, 0, 0, 0, 0]),  # ** right-associative
        ("x - 1 - 1 == 1", [0, 0, 0, 1, 0, 0]),  # - left-associative
        ("z / 2 / 2 == 1", [0, 0, 1, 0, 0, 0]),
        ("x + 1 > 3 == True", [0, 0, 0, 0, 0, 0]),  # chain: (x+1 > 3) and (3 == True)
    ],
)
def test_precedence(cloud, expr, want):
    assert ev(cloud, expr) == want


def test_issue_example(cloud):
    assert ev(cloud, "segment_id >= 0 and segment_size > 50 and planarity > 0.5") == [0, 1, 0, 1, 0, 1]


# ------------------------------------------------------------------ NaN and types
@pytest.mark.parametrize(
    "expr, want",
    [
        ("planarity > 0.5", [0, 1, 0, 1, 0, 1]),
        ("planarity <= 0.5", [1, 0, 0, 0, 1, 0]),
        ("planarity != 0.6", [1, 0, 0, 1, 1, 1]),  # NaN comparisons are False, also !=
        ("planarity == planarity", [1, 1, 0, 1, 1, 1]),
        ("not planarity == planarity", [0, 0, 1, 0, 0, 0]),  # how to select NaN
        ("not (planarity > 0.5)", [1, 0, 1, 0, 1, 0]),  # not of a False comparison keeps NaN points
        ("planarity in [0.6, 0.9]", [0, 1, 0, 1, 0, 0]),
        ("planarity not in [0.6, 0.9]", [1, 0, 0, 0, 1, 1]),
        ("planarity * 0 == 0", [1, 1, 0, 1, 1, 1]),  # NaN propagates through arithmetic
        ("x / 0 > 1", [0, 1, 1, 1, 1, 1]),  # 0/0 = NaN -> False, k/0 = inf
    ],
)
def test_nan(cloud, expr, want):
    assert ev(cloud, expr) == want


def test_float32_equality_and_integer_arithmetic(cloud):
    assert ev(cloud, "planarity == 0.1") == [1, 0, 0, 0, 0, 0]  # stored as float32
    assert ev(cloud, "planarity_r0.50 == 0.8") == [0, 0, 0, 1, 1, 1]
    # uint8 attributes must not wrap around
    assert ev(cloud, "return_number - number_of_returns < 0") == [0, 1, 0, 1, 1, 0]
    assert ev(cloud, "return_number == number_of_returns") == [1, 0, 1, 0, 0, 1]
    assert ev(cloud, "segment_id % 2 == 0") == [0, 1, 0, 1, 1, 0]
    assert ev(cloud, "segment_size ** -1 > 0.015") == [1, 0, 1, 1, 1, 1]  # int ** negative -> float; 0 ** -1 = inf
    assert ev(cloud, "9 ** 9 ** 9 ** 9 > 1") == [1] * 6  # huge constants overflow to inf, no hang


def test_names(cloud):
    assert ev(cloud, "`planarity_r0.50` > 0.6") == [0, 0, 0, 1, 1, 1]
    assert names_in("segment_id >= 0 and planarity_r0.50 > x") == ["segment_id", "planarity_r0.50", "x"]
    e = parse("segment_size > 55")
    assert isinstance(e, Expression)
    assert ev(cloud, e) == [0, 1, 0, 1, 1, 0]


# ------------------------------------------------------------------ errors
def test_unknown_name_lists_attributes(cloud):
    with pytest.raises(LidarfxError) as exc:
        evaluate(cloud, "segment_id >= 0 and planarty > 0.5")
    msg = str(exc.value)
    assert "'planarty'" in msg and "column 21" in msg
    assert "available: x, y, z, segment_id, segment_size, planarity" in msg
    assert "\n" not in msg


@pytest.mark.parametrize(
    "expr, words",
    [
        ("__import__('os')", "function calls are not allowed"),
        ("__import__('os').system('ls') == 0", "function calls are not allowed"),
        ("open('/etc/passwd')", "function calls are not allowed"),
        ("abs(x) > 1", "function calls are not allowed"),
        ("x.__class__ == 1", "attribute access is not allowed"),
        ("os.system == 1", "attribute access is not allowed"),
        ("x[0] > 1", "indexing is not allowed"),
        ("(x)(1) > 1", "calling or indexing"),
        ("lambda: 1", "not allowed"),
        ("'a' == x", "strings are not allowed"),
        ('x == "a"', "strings are not allowed"),
        ("x = 1", "use '=='"),
        ("x > 1 && y < 2", "use 'and'"),
        ("x > 1 | y < 2", "use 'or'"),
        ("~(x > 1)", "use 'not'"),
        ("x // 2 == 1", "floor division"),
        ("x > 1; y > 1", "only one expression"),
        ("{1} == x", "not allowed"),
        ("", "empty expression"),
        ("x >", "expected a number"),
        ("(x > 1", "expected ')'"),
        ("x > 1)", "unexpected ')'"),
        ("x in y", "'in' needs a list"),
        ("[1, 2] == x", "only allowed after 'in'"),
        ("(x, y) == 1", "tuples are only allowed after 'in'"),
        ("x", "not a condition"),
        ("x + 1", "not a condition"),
        ("x > 1 and 2", "not a condition"),
        ("(x > 1) + 1 > 0", "arithmetic"),
        ("x in [y]", "must hold numbers"),
        ("3x > 1", "invalid number"),
        ("x $ 1", "unexpected character"),
        ("x > 1 and", "expected a number"),
        ("and x > 1", "unexpected keyword"),
    ],
)
def test_rejected(cloud, expr, words):
    with pytest.raises(LidarfxError) as exc:
        evaluate(cloud, expr)
    assert words in str(exc.value)
    assert "\n" not in str(exc.value)


def test_never_eval(cloud, monkeypatch):
    import builtins

    def boom(*a, **k):  # pragma: no cover - must not be called
        raise AssertionError("eval/exec/compile used")

    for name in ("eval", "exec", "compile"):
        monkeypatch.setattr(builtins, name, boom)
    assert ev(cloud, "segment_id >= 0 and planarity > 0.5") == [0, 1, 0, 1, 0, 1]


# ------------------------------------------------------------------ select()
def test_select_subset(cloud):
    out = select(cloud, "segment_size > 50")
    assert len(out) == 4 and out.names == cloud.names
    assert out["segment_id"].tolist() == [0, 2, 2, 3]
    assert out.meta["selection"] == {"where": "segment_size > 50", "invert": False, "kept": 4, "total": 6}
    inv = select(cloud, "segment_size > 50", invert=True)
    assert inv["segment_id"].tolist() == [-1, 1]
    assert len(select(cloud, "x > 100")) == 0


# ------------------------------------------------------------------ CLI
def _write(cloud, tmp_path):
    path = tmp_path / "in.laz"
    lidarfx.write(cloud, path)
    return path


def test_cli_select(cloud, tmp_path, capsys):
    cloud = PointCloud(cloud.xyz, {k: v for k, v in cloud.attrs.items() if k not in ("withheld", "return_number", "number_of_returns")})
    src = _write(cloud, tmp_path)
    out = tmp_path / "out.laz"
    assert main(["select", str(src), str(out), "--where", "segment_id >= 0 and segment_size > 50 and planarity > 0.5"]) == 0
    assert "kept 3 of 6 points" in capsys.readouterr().err
    back = lidarfx.read(out)
    assert back["segment_id"].tolist() == [0, 2, 3]
    assert main(["select", str(src), str(tmp_path / "inv.laz"), "-w", "segment_id >= 0", "--invert", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["kept"] == 1 and summary["total"] == 6 and summary["invert"] is True
    assert len(lidarfx.read(tmp_path / "inv.laz")) == 1
    # attributes with a scale suffix survive LAS extra bytes and can be selected
    assert main(["select", str(src), str(tmp_path / "s.npz"), "-q", "-w", "planarity_r0.50 > 0.6"]) == 0
    assert len(lidarfx.read(tmp_path / "s.npz")) == 3


@pytest.mark.parametrize(
    "expr, words",
    [
        ("segment_id >= 0 and __import__('os')", "function calls are not allowed"),
        ("segment_id >", "invalid expression"),
        ("planarty > 0.5", "available:"),
    ],
)
def test_cli_select_bad_expression(cloud, tmp_path, capsys, expr, words):
    src = _write(PointCloud(cloud.xyz, {"segment_id": cloud["segment_id"], "planarity": cloud["planarity"]}), tmp_path)
    out = tmp_path / "out.laz"
    assert main(["select", str(src), str(out), "--where", expr]) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lidarfx: error:") and words in lines[0]
    assert not out.exists()
