"""Selection by criteria: a safe, vectorised expression over point attributes (docs/segmentation.md §5).

>>> import lidarfx
>>> from lidarfx.select import evaluate, select
>>> mask = evaluate(cloud, "segment_id >= 0 and segment_size > 50 and planarity > 0.5")  # doctest: +SKIP
>>> roofs = select(cloud, "classification in [6, 17] and not (z < 40)")                    # doctest: +SKIP

The expression is parsed by a small recursive-descent parser written for this
grammar — never by Python's ``eval`` — and evaluated with numpy over whole
attribute arrays.  Grammar (loosest binding first)::

    expr       := or_expr
    or_expr    := and_expr ("or" and_expr)*
    and_expr   := not_expr ("and" not_expr)*
    not_expr   := "not" not_expr | comparison
    comparison := sum (compare_op sum | ["not"] "in" list)*   # chains: a < b < c
    compare_op := "<" | "<=" | ">" | ">=" | "==" | "!="
    sum        := term (("+" | "-") term)*
    term       := unary (("*" | "/" | "%") unary)*
    unary      := ("-" | "+") unary | power
    power      := atom ["**" unary]                             # right-associative
    atom       := NUMBER | NAME | "True" | "False" | "(" expr ")"
    list       := "[" [sum ("," sum)*] "]"  |  "(" ... ")"

Names are the attributes of the cloud plus ``x``, ``y``, ``z`` (world
coordinates; they take precedence over attributes of the same name).  A name
may contain a decimal scale suffix (``planarity_r0.50``); any other name can
be quoted with back-ticks (```my attr` > 3``).  ``and``/``or``/``not`` work
elementwise.  Any comparison with a NaN operand is False (also ``!=`` and
``not in``), so ``not (planarity > 0.5)`` keeps NaN points while
``planarity <= 0.5`` drops them.  Integer attributes are evaluated as int64,
float32 attributes are compared with constants rounded to float32 (so
``planarity == 0.1`` matches a stored float32 0.1).
"""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError

__all__ = ["Expression", "evaluate", "names_in", "parse", "select"]

_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*(?:\.\d+)?(?![A-Za-z0-9_]))
  | (?P<quoted>`[^`]*`)
  | (?P<op>\*\*|<=|>=|==|!=|//|&&|\|\||[-+*/%<>()\[\],=.&|~!^'"@:;{}])
    """,
    re.VERBOSE,
)

_KEYWORDS = {"and", "or", "not", "in", "True", "False"}
_HINTS = {
    "=": "use '==' to compare",
    "&&": "use 'and'",
    "&": "use 'and'",
    "||": "use 'or'",
    "|": "use 'or'",
    "~": "use 'not'",
    "!": "use 'not' (or '!=')",
    "//": "floor division is not supported; use '/' or '%'",
    "^": "use '**' for powers",
    "'": "strings are not allowed",
    '"': "strings are not allowed",
    "{": "sets/dicts are not allowed; use [..]",
    "}": "sets/dicts are not allowed",
    "@": "matrix operations are not allowed",
    ":": "slices / lambdas are not allowed",
    ";": "only one expression is allowed",
    ".": "attribute access is not allowed",
}


@dataclass(frozen=True)
class _Tok:
    kind: str  # num, name, op, kw, end
    text: str
    pos: int


def _tokenize(expr: str) -> list[_Tok]:
    toks: list[_Tok] = []
    pos = 0
    while pos < len(expr):
        m = _TOKEN.match(expr, pos)
        if not m:
            raise _error(expr, pos, f"unexpected character {expr[pos]!r}")
        kind = m.lastgroup
        text = m.group()
        if kind == "name" and text in _KEYWORDS:
            kind = "kw"
        elif kind == "quoted":
            kind, text = "name", text[1:-1]
            if not text:
                raise _error(expr, pos, "empty quoted name")
        elif kind == "num" and m.end() < len(expr) and (expr[m.end()].isalpha() or expr[m.end()] == "_"):
            raise _error(expr, pos, f"invalid number {text + expr[m.end()]!r}...")
        if kind != "ws":
            toks.append(_Tok(kind, text, pos))
        pos = m.end()
    toks.append(_Tok("end", "", len(expr)))
    return toks


SHOWN = 80
"""Longest expression an error message repeats whole; a longer one is shown around the problem."""


def shown_expression(expr: str, pos: int | None = None) -> str:
    """``expr`` for an error message: whole (quoted) up to :data:`SHOWN` characters, else the
    characters around column ``pos + 1`` (the start without ``pos``) with "..." for the rest."""
    if len(expr) <= SHOWN:
        return repr(expr)
    half = SHOWN // 2
    a = max(0, min(len(expr) - SHOWN, (pos or 0) - half))
    b = a + SHOWN
    return ("..." if a else "") + repr(expr[a:b]) + ("..." if b < len(expr) else "") + f" ({len(expr):,} characters)"


def _error(expr: str, pos: int, msg: str) -> LidarfxError:
    return LidarfxError(f"invalid expression at column {pos + 1}: {msg} (in {shown_expression(expr, pos)})")


# ----------------------------------------------------------------------------
# AST: tuples ("num", value) ("name", str) ("bool", b) ("neg", e) ("bin", op, a, b)
# ("cmp", [ops], [operands]) ("in", negate, e, [items]) ("and"/"or", [e...]) ("not", e)
# ----------------------------------------------------------------------------
MAX_DEPTH = 50
"""Deepest nesting of parentheses, ``not``, signs and powers an expression may have, and (times four)
of its tree (a sum of 200 terms): deeper is refused, not a recursion error."""


class _Parser:
    def __init__(self, expr: str) -> None:
        self.expr = expr
        self.toks = _tokenize(expr)
        self.i = 0
        self.depth = 0

    def nest(self, step: int) -> None:
        """Enter (+1) or leave (-1) a nested part; refuses more than :data:`MAX_DEPTH` levels."""
        self.depth += step
        if self.depth > MAX_DEPTH:
            raise self.fail(f"expression nested too deeply (more than {MAX_DEPTH} levels)")

    # helpers
    @property
    def tok(self) -> _Tok:
        return self.toks[self.i]

    def take(self) -> _Tok:
        t = self.toks[self.i]
        self.i += 1
        return t

    def at(self, kind: str, *texts: str) -> bool:
        t = self.tok
        return t.kind == kind and (not texts or t.text in texts)

    def fail(self, msg: str, tok: _Tok | None = None) -> LidarfxError:
        t = tok or self.tok
        return _error(self.expr, t.pos, msg)

    def expect_op(self, text: str) -> _Tok:
        if not self.at("op", text):
            raise self.fail(f"expected {text!r}, got {self._desc(self.tok)}")
        return self.take()

    @staticmethod
    def _desc(t: _Tok) -> str:
        return "end of expression" if t.kind == "end" else repr(t.text)

    # grammar
    def parse(self):
        if self.tok.kind == "end":
            raise self.fail("empty expression")
        node = self.or_expr()
        if self.tok.kind != "end":
            t = self.tok
            if t.kind == "op" and t.text in _HINTS:
                raise self.fail(f"{_HINTS[t.text]} (got {t.text!r})")
            raise self.fail(f"unexpected {self._desc(t)}")
        return node

    def or_expr(self):
        items = [self.and_expr()]
        while self.at("kw", "or"):
            self.take()
            items.append(self.and_expr())
        return items[0] if len(items) == 1 else ("or", items)

    def and_expr(self):
        items = [self.not_expr()]
        while self.at("kw", "and"):
            self.take()
            items.append(self.not_expr())
        return items[0] if len(items) == 1 else ("and", items)

    def not_expr(self):
        if self.at("kw", "not"):
            self.take()
            self.nest(1)
            node = ("not", self.not_expr())
            self.nest(-1)
            return node
        return self.comparison()

    _CMP = ("<", "<=", ">", ">=", "==", "!=")

    def comparison(self):
        first = self.sum()
        parts = []  # ("cmp", op, rhs) or ("in", negate, items)
        while True:
            if self.at("op", *self._CMP):
                op = self.take().text
                parts.append(("cmp", op, self.sum()))
            elif self.at("kw", "in"):
                self.take()
                parts.append(("in", False, self.list_literal()))
            elif self.at("kw", "not") and self.toks[self.i + 1].kind == "kw" and self.toks[self.i + 1].text == "in":
                self.i += 2
                parts.append(("in", True, self.list_literal()))
            else:
                break
        if not parts:
            return first
        # a < b <= c  ->  (a < b) and (b <= c), like Python
        terms = []
        left = first
        for p in parts:
            if p[0] == "cmp":
                terms.append(("cmp", p[1], left, p[2]))
                left = p[2]
            else:
                terms.append(("in", p[1], left, p[2]))
        return terms[0] if len(terms) == 1 else ("and", terms)

    def list_literal(self):
        if not (self.at("op", "[") or self.at("op", "(")):
            raise self.fail(f"'in' needs a list like [1, 2, 3], got {self._desc(self.tok)}")
        close = "]" if self.take().text == "[" else ")"
        items = []
        if not self.at("op", close):
            items.append(self.sum())
            while self.at("op", ","):
                self.take()
                if self.at("op", close):
                    break
                items.append(self.sum())
        self.expect_op(close)
        return items

    def sum(self):
        node = self.term()
        while self.at("op", "+", "-"):
            op = self.take().text
            node = ("bin", op, node, self.term())
        return node

    def term(self):
        node = self.unary()
        while self.at("op", "*", "/", "%"):
            op = self.take().text
            node = ("bin", op, node, self.unary())
        return node

    def unary(self):
        if self.at("op", "-", "+"):
            op = self.take().text
            self.nest(1)
            inner = self.unary()
            self.nest(-1)
            return ("neg", inner) if op == "-" else inner
        return self.power()

    def power(self):
        node = self.atom()
        if self.at("op", "**"):
            self.take()
            self.nest(1)
            node = ("bin", "**", node, self.unary())
            self.nest(-1)
        return node

    def atom(self):
        t = self.tok
        if t.kind == "num":
            self.take()
            return ("num", float(t.text))
        if t.kind == "kw" and t.text in ("True", "False"):
            self.take()
            return ("bool", t.text == "True")
        if t.kind == "name":
            self.take()
            nxt = self.tok
            if nxt.kind == "op" and nxt.text == "(":
                raise self.fail(f"function calls are not allowed ({t.text}(...))", t)
            if nxt.kind == "op" and nxt.text == ".":
                raise self.fail(f"attribute access is not allowed ({t.text}.…)", t)
            if nxt.kind == "op" and nxt.text == "[":
                raise self.fail(f"indexing is not allowed ({t.text}[...])", t)
            return ("name", t.text, t.pos)
        if t.kind == "op" and t.text == "(":
            self.take()
            self.nest(1)
            node = self.or_expr()
            self.nest(-1)
            if self.at("op", ","):
                raise self.fail("tuples are only allowed after 'in'")
            self.expect_op(")")
            if self.at("op", "(", "["):
                raise self.fail("calling or indexing an expression is not allowed")
            return node
        if t.kind == "op" and t.text == "[":
            raise self.fail("a list is only allowed after 'in'")
        if t.kind == "op" and t.text in _HINTS:
            raise self.fail(f"{_HINTS[t.text]} (got {t.text!r})")
        if t.kind == "kw":
            raise self.fail(f"unexpected keyword {t.text!r}")
        raise self.fail(f"expected a number, a name or '(', got {self._desc(t)}")


@dataclass(frozen=True)
class Expression:
    """A parsed expression: ``source`` text and the tree; reuse it on many clouds."""

    source: str
    tree: Any

    def names(self) -> list[str]:
        """Attribute / coordinate names the expression uses, in order of appearance."""
        out: list[str] = []

        def walk(node):
            if isinstance(node, tuple):
                if node[0] == "name":
                    if node[1] not in out:
                        out.append(node[1])
                    return
                for x in node[1:]:
                    walk(x)
            elif isinstance(node, list):
                for x in node:
                    walk(x)

        walk(self.tree)
        return out


def parse(expr: str) -> Expression:
    """Parse ``expr`` (no evaluation); raises :class:`LidarfxError` with the column of the problem."""
    if not isinstance(expr, str):
        raise LidarfxError(f"the expression must be a string, got {type(expr).__name__}")
    if len(expr) > 10_000:
        raise LidarfxError("expression too long (more than 10,000 characters)")
    tree = _Parser(expr).parse()
    if _tree_depth(tree) > 4 * MAX_DEPTH:  # x + x + ... parses in a loop but evaluates recursively
        raise LidarfxError(f"expression too deep (more than {4 * MAX_DEPTH} nested operations, e.g. terms of a sum)")
    return Expression(expr, tree)


def _tree_depth(tree) -> int:
    """Depth of a parse tree (counted without recursion)."""
    deepest, todo = 0, [(tree, 1)]
    while todo:
        node, d = todo.pop()
        deepest = max(deepest, d)
        for child in node[1:] if isinstance(node, tuple) else node:
            if isinstance(child, (tuple, list)):
                todo.append((child, d + 1))
    return deepest


def names_in(expr: str) -> list[str]:
    """Names used by ``expr``."""
    return parse(expr).names()


# ----------------------------------------------------------------------------
# evaluation
# ----------------------------------------------------------------------------
_ARITH: dict[str, Callable[[Any, Any], Any]] = {
    "+": np.add,
    "-": np.subtract,
    "*": np.multiply,
    "/": np.true_divide,
    "%": np.mod,
    "**": np.power,
}
_COMPARE: dict[str, Callable[[Any, Any], Any]] = {
    "<": np.less,
    "<=": np.less_equal,
    ">": np.greater,
    ">=": np.greater_equal,
    "==": np.equal,
    "!=": np.not_equal,
}


def _is_bool(v: Any) -> bool:
    return np.asarray(v).dtype == np.bool_


def _nan_free(v: Any) -> Any:
    """True where ``v`` is not NaN (scalar True for non-float values)."""
    a = np.asarray(v)
    if a.dtype.kind == "f":
        return ~np.isnan(a)
    return True


class _Evaluator:
    def __init__(self, expr: Expression, cloud: PointCloud) -> None:
        self.expr = expr
        self.cloud = cloud
        self.cache: dict[str, np.ndarray] = {}

    def fail(self, msg: str) -> LidarfxError:
        return LidarfxError(f"invalid expression: {msg} (in {shown_expression(self.expr.source)})")

    def lookup(self, name: str, pos: int) -> np.ndarray:
        if name in self.cache:
            return self.cache[name]
        if name in ("x", "y", "z"):
            arr = self.cloud.xyz[:, "xyz".index(name)]
        elif name in self.cloud:
            arr = np.asarray(self.cloud[name])
            if arr.dtype.kind in "iu":
                arr = arr.astype(np.int64)
            elif arr.dtype.kind not in "fb":
                raise LidarfxError(f"attribute {name!r} has type {arr.dtype}, which expressions cannot use")
        else:
            avail = ", ".join(["x", "y", "z"] + [n for n in self.cloud.names if n not in ("x", "y", "z")])
            raise LidarfxError(
                f"unknown name {name!r} at column {pos + 1} of the expression; available: {avail}"
            )
        self.cache[name] = arr
        return arr

    def value(self, node) -> Any:
        kind = node[0]
        if kind == "num":
            return np.float64(node[1])
        if kind == "bool":
            return np.bool_(node[1])
        if kind == "name":
            return self.lookup(node[1], node[2])
        if kind == "neg":
            v = self.value(node[1])
            if _is_bool(v):
                raise self.fail("'-' applied to a condition")
            return np.negative(v)
        if kind == "bin":
            a, b = self.value(node[2]), self.value(node[3])
            if _is_bool(a) or _is_bool(b):
                raise self.fail(f"arithmetic {node[1]!r} on a condition; use and/or/not")
            if node[1] in ("/", "**"):
                a = np.asarray(a, dtype=np.float64) if np.asarray(a).dtype.kind != "f" else a
                b = np.asarray(b, dtype=np.float64) if np.asarray(b).dtype.kind != "f" else b
            return _ARITH[node[1]](a, b)
        return self.condition(node)

    def condition(self, node) -> Any:
        kind = node[0]
        if kind == "cmp":
            a, b = self.value(node[2]), self.value(node[3])
            a, b = _align_float32(a, b)
            res = _COMPARE[node[1]](a, b)
            return res & _nan_free(a) & _nan_free(b)
        if kind == "in":
            v = self.value(node[2])
            if _is_bool(v):
                raise self.fail("'in' applied to a condition")
            items = [self.value(it) for it in node[3]]
            for it in items:
                if np.ndim(it) != 0:
                    raise self.fail("the list after 'in' must hold numbers (no attributes)")
                if _is_bool(it):
                    raise self.fail("the list after 'in' must hold numbers")
            vals = np.asarray(items, dtype=np.float64)
            va = np.asarray(v)
            if va.dtype == np.float32:
                vals = vals.astype(np.float32)
            hit = np.isin(va, vals)
            if node[1]:
                hit = ~hit
            return hit & _nan_free(va)
        if kind in ("and", "or"):
            acc = None
            for sub in node[1]:
                v = self.condition(sub)
                acc = v if acc is None else (acc & v if kind == "and" else acc | v)
            return acc
        if kind == "not":
            return ~np.asarray(self.condition(node[1]), dtype=bool)
        v = self.value(node)
        if not _is_bool(v):
            what = "a number" if np.ndim(v) == 0 else "numbers"
            raise self.fail(f"{_describe(node)} gives {what}, not a condition; compare it, e.g. '{_describe(node)} > 0'")
        return v


def _describe(node) -> str:
    if node[0] == "name":
        return node[1]
    if node[0] == "num":
        return f"{node[1]:g}"
    return "this part"


def _align_float32(a: Any, b: Any) -> tuple[Any, Any]:
    """Compare float32 attributes with constants at float32 precision."""
    aa, bb = np.asarray(a), np.asarray(b)
    if aa.dtype == np.float32 and bb.ndim == 0 and bb.dtype.kind in "fiu":
        return a, np.float32(bb)
    if bb.dtype == np.float32 and aa.ndim == 0 and aa.dtype.kind in "fiu":
        return np.float32(aa), b
    return a, b


def evaluate(cloud: PointCloud, expr: str | Expression) -> np.ndarray:
    """Boolean mask (length n) of the points where ``expr`` holds.

    Raises :class:`LidarfxError` for a syntax error (with the column), an
    unknown name (listing the available attributes) or a non-condition.
    """
    if not isinstance(cloud, PointCloud):
        raise LidarfxError("evaluate expects a PointCloud")
    e = expr if isinstance(expr, Expression) else parse(expr)
    ev = _Evaluator(e, cloud)
    with np.errstate(all="ignore"):
        try:
            res = ev.condition(e.tree)
        except (OverflowError, ZeroDivisionError, ValueError, TypeError) as exc:
            raise LidarfxError(f"cannot evaluate {shown_expression(e.source)}: {exc}") from None
    res = np.asarray(res, dtype=bool)
    if res.ndim == 0:
        res = np.full(len(cloud), bool(res))
    return res


def select(cloud: PointCloud, expr: str | Expression, *, invert: bool = False) -> PointCloud:
    """The points of ``cloud`` where ``expr`` holds (or does not hold, with ``invert``)."""
    mask = evaluate(cloud, expr)
    if invert:
        mask = ~mask
    out = cloud.subset(mask)
    out.meta = dict(out.meta)
    source = expr.source if isinstance(expr, Expression) else str(expr)
    out.meta["selection"] = {"where": source, "invert": bool(invert), "kept": int(mask.sum()), "total": len(cloud)}
    return out
