"""Transition conditions as sets of conjunctions, for the static checks of mission graphs (§5.4).

A condition (docs/decisions.md D9) is rewritten in disjunctive normal form over *literals*: an
atom, possibly negated. Atoms are the calls (``done()``, ``outcome('x')``), numeric comparisons of
one variable with a constant (kept as an interval, so ``elapsed > 30`` implies ``elapsed > 10``)
and any other expression by its normalised text. The reasoning is purely syntactic and errs on
the side of silence: it proves an implication only when every conjunction of one condition
contains (literals implying) every literal of a conjunction of the other — enough for the
mistakes that matter, ``done()`` before ``done() and x``, identical conditions, ``a or b`` before
``a`` — and never claims a condition is dead unless it is.

Negation stays on its atom: a missing value makes every comparison false (D9), so
``not (x < 3)`` is *not* ``x >= 3``.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Iterable
from dataclasses import dataclass

from ckmconf.expressions import Condition

MAX_CONJUNCTIONS = 256
"""Past this many conjunctions a condition is not analysed (its checks are skipped)."""


@dataclass(frozen=True)
class Interval:
    """The values a comparison with a constant admits; bounds may be open or infinite."""

    low: float = -math.inf
    low_closed: bool = False
    high: float = math.inf
    high_closed: bool = False

    def within(self, other: Interval) -> bool:
        """True if every value this interval admits is admitted by ``other`` (so ``x > 30`` ⊆ ``x > 10``)."""
        low_ok = self.low > other.low or (self.low == other.low and (other.low_closed or not self.low_closed))
        high_ok = self.high < other.high or (self.high == other.high and (other.high_closed or not self.high_closed))
        return low_ok and high_ok

    def empty_with(self, other: Interval) -> bool:
        """True if no value satisfies both intervals (e.g. ``x < 3 and x > 5``)."""
        # The tighter bound wins: for equal values an open bound is tighter than a closed one.
        low, low_open = max((self.low, not self.low_closed), (other.low, not other.low_closed))
        high, high_closed = min((self.high, self.high_closed), (other.high, other.high_closed))
        return low > high or (low == high and (low_open or not high_closed))


Atom = tuple[object, ...]
"""("call", name, *args) | ("cmp", subject, Interval) | ("expr", text)"""


@dataclass(frozen=True)
class Literal:
    """An atom (``Atom``), possibly negated: one factor of a conjunction in the DNF of a condition."""

    positive: bool
    atom: Atom

    def __str__(self) -> str:
        text = _atom_text(self.atom)
        return text if self.positive else f"not {text}"


Conjunction = frozenset[Literal]


def _atom_text(atom: Atom) -> str:
    if atom[0] == "call":
        return f"{atom[1]}({', '.join(repr(a) for a in atom[2:])})"
    if atom[0] == "cmp":
        interval = atom[2]
        assert isinstance(interval, Interval)
        if interval.low == interval.high:
            return f"{atom[1]} == {interval.low:g}"
        parts = []
        if interval.low > -math.inf:
            parts.append(f"{atom[1]} {'>=' if interval.low_closed else '>'} {interval.low:g}")
        if interval.high < math.inf:
            parts.append(f"{atom[1]} {'<=' if interval.high_closed else '<'} {interval.high:g}")
        return " and ".join(parts)
    return str(atom[1])


def call(name: str, *args: object) -> Literal:
    """A positive call literal, e.g. ``call("outcome", "arrived")``."""
    return Literal(True, ("call", name, *args))


# ----------------------------------------------------------------------------- normal form


def dnf(condition: Condition) -> list[Conjunction] | None:
    """The condition's conjunctions (an empty list: never true); None when it is too large."""
    try:
        return _dnf(condition.tree.body, True)
    except _TooLarge:
        return None


class _TooLarge(Exception):
    pass


def _dnf(node: ast.AST, positive: bool) -> list[Conjunction]:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        return _dnf(node.operand, not positive)
    if isinstance(node, ast.BoolOp):
        parts = [_dnf(v, positive) for v in node.values]
        # De Morgan: a negated "and" is an "or" of negations, and the reverse.
        if isinstance(node.op, ast.Or) == positive:
            return _dedupe(c for part in parts for c in part)
        product: list[Conjunction] = [frozenset()]
        for part in parts:
            product = _dedupe(a | b for a in product for b in part)
            if len(product) > MAX_CONJUNCTIONS:
                raise _TooLarge
        return product
    if isinstance(node, ast.Constant):
        return [frozenset()] if bool(node.value) == positive else []
    if isinstance(node, ast.Name) and node.id in ("True", "False"):
        return [frozenset()] if (node.id == "True") == positive else []
    if isinstance(node, ast.Compare) and len(node.ops) > 1:
        operands = [node.left, *node.comparators]
        pairs = [
            ast.Compare(left=a, ops=[op], comparators=[b])
            for a, op, b in zip(operands[:-1], node.ops, operands[1:], strict=True)
        ]
        return _dnf(ast.BoolOp(op=ast.And(), values=list(pairs)), positive)
    return [frozenset({Literal(positive, _atom(node))})]


def _dedupe(conjunctions: Iterable[Conjunction]) -> list[Conjunction]:
    return list(dict.fromkeys(conjunctions))


def _atom(node: ast.AST) -> Atom:
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        return ("call", node.func.id, *(a.value for a in node.args if isinstance(a, ast.Constant)))
    if isinstance(node, ast.Compare):
        interval = _interval(node)
        if interval is not None:
            return ("cmp", *interval)
    return ("expr", ast.unparse(node))


def _number(node: ast.AST) -> float | None:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _number(node.operand)
        return None if value is None else (-value if isinstance(node.op, ast.USub) else value)
    if isinstance(node, ast.Constant) and isinstance(node.value, int | float) and not isinstance(node.value, bool):
        return float(node.value)
    return None


_FLIP = {ast.Lt: ast.Gt, ast.LtE: ast.GtE, ast.Gt: ast.Lt, ast.GtE: ast.LtE, ast.Eq: ast.Eq}


def _interval(node: ast.Compare) -> tuple[str, Interval] | None:
    """``subject op constant`` (either way round) as the subject and the interval it must lie in."""
    left, op, right = node.left, node.ops[0], node.comparators[0]
    if type(op) not in _FLIP:
        return None
    if _number(left) is not None and _number(right) is None:
        left, right, op = right, left, _FLIP[type(op)]()
    value = _number(right)
    if value is None or not isinstance(left, ast.Name | ast.Attribute):
        return None
    subject = ast.unparse(left)
    if isinstance(op, ast.Lt | ast.LtE):
        return subject, Interval(high=value, high_closed=isinstance(op, ast.LtE))
    if isinstance(op, ast.Gt | ast.GtE):
        return subject, Interval(low=value, low_closed=isinstance(op, ast.GtE))
    return subject, Interval(value, True, value, True)


# ----------------------------------------------------------------------------- reasoning


def literal_implies(a: Literal, b: Literal) -> bool:
    """Whether ``a`` holding guarantees ``b`` holds."""
    if a == b:
        return True
    if a.positive != b.positive or a.atom[0] != "cmp" or b.atom[0] != "cmp" or a.atom[1] != b.atom[1]:
        return False
    inner, outer = (a.atom[2], b.atom[2]) if a.positive else (b.atom[2], a.atom[2])
    assert isinstance(inner, Interval) and isinstance(outer, Interval)
    return inner.within(outer)


def conjunction_implies(a: Conjunction, b: Conjunction) -> bool:
    """Whether conjunction ``a`` holding guarantees ``b`` holds (every literal of b is covered)."""
    return all(any(literal_implies(x, y) for x in a) for y in b)


def implies(a: list[Conjunction], b: list[Conjunction]) -> bool:
    """Whether condition ``a`` holding guarantees condition ``b`` holds."""
    return all(any(conjunction_implies(x, y) for y in b) for x in a)


def contradictory(conjunction: Conjunction, *, behavior: bool) -> bool:
    """Whether a conjunction can never hold.

    Besides ``x and not x`` and disjoint intervals on one variable, a behavior ends either done or
    failed (never both), and a nested mission ends in exactly one outcome.
    """
    positives = [lit.atom for lit in conjunction if lit.positive]
    negatives = {lit.atom for lit in conjunction if not lit.positive}
    if any(atom in negatives for atom in positives):
        return True
    if behavior and ("call", "done") in positives and ("call", "failed") in positives:
        return True
    if len({a for a in positives if a[:2] == ("call", "outcome")}) > 1:
        return True
    intervals: dict[object, list[Interval]] = {}
    for atom in positives:
        if atom[0] == "cmp" and isinstance(atom[2], Interval):
            intervals.setdefault(atom[1], []).append(atom[2])
    return any(a.empty_with(b) for found in intervals.values() for i, a in enumerate(found) for b in found[i + 1 :])


def describe(conjunction: Conjunction) -> str:
    """A conjunction as condition text (for messages)."""
    return " and ".join(sorted(str(lit) for lit in conjunction)) or "True"
