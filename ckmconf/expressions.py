"""The condition language of transitions (§5.2, ``<Transition when>``) and controller switches (§3.1.2.7).

A condition is a Python-like boolean expression, parsed with ``ast`` and checked against a
whitelist: comparisons, and/or/not, numbers, strings, names, ``alias.field`` and calls
of the functions a context offers. Nothing is ever passed to ``eval``.
"""

from __future__ import annotations

import ast
import operator
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any


class ExpressionError(ValueError):
    """A condition that does not parse or uses something its context does not offer."""

    def __init__(self, message: str, column: int = 0) -> None:
        super().__init__(message)
        self.column = column


@dataclass(frozen=True)
class Vocabulary:
    """What a context offers: functions with their argument count, and plain names."""

    functions: Mapping[str, int]
    names: frozenset[str] = frozenset()
    attributes: bool = False


TRANSITION = Vocabulary(
    functions={"done": 0, "failed": 0, "timeout": 0, "outcome": 1, "signal": 1, "lost": 1},
    names=frozenset({"progress", "elapsed", "performance"}),
    attributes=True,
)
SWITCH = Vocabulary(functions={"alarm": 1, "stale": 1, "value": 1}, names=frozenset({"elapsed"}))


@dataclass
class Condition:
    """A parsed ``when`` condition (``<Transition>``, ``<Switch>``) and the references it makes (for checks)."""

    text: str
    tree: ast.Expression
    calls: list[tuple[str, tuple[Any, ...]]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    attributes: list[tuple[str, str]] = field(default_factory=list)


_COMPARE: dict[type[ast.cmpop], Callable[[Any, Any], bool]] = {
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
}


def parse(text: str, vocabulary: Vocabulary) -> Condition:
    """Parse and check a condition; raises ExpressionError naming the offending part."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"syntax error in condition {text!r}: {exc.msg}", (exc.offset or 1) - 1) from None
    except (RecursionError, MemoryError, ValueError):
        raise ExpressionError(f"condition {text!r} is nested too deeply or holds invalid characters") from None
    condition = Condition(text, tree)
    try:
        _check(tree.body, vocabulary, condition)
    except RecursionError:
        raise ExpressionError(f"condition {text!r} is nested too deeply") from None
    return condition


def _check(node: ast.AST, vocab: Vocabulary, out: Condition) -> None:
    if isinstance(node, ast.BoolOp):
        for value in node.values:
            _check(value, vocab, out)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub, ast.UAdd)):
        _check(node.operand, vocab, out)
    elif isinstance(node, ast.Compare):
        if not all(type(op) in _COMPARE for op in node.ops):
            raise ExpressionError("only ==, !=, <, <=, >, >= comparisons are allowed", node.col_offset)
        for part in [node.left, *node.comparators]:
            _check(part, vocab, out)
    elif isinstance(node, ast.Constant) and isinstance(node.value, (int, float, str, bool)):
        return
    elif isinstance(node, ast.Name):
        if node.id in ("True", "False"):
            return
        if node.id not in vocab.names:
            raise ExpressionError(f"unknown name {node.id!r} (known: {_known(vocab)})", node.col_offset)
        out.names.append(node.id)
    elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and vocab.attributes:
        out.attributes.append((node.value.id, node.attr))
    elif isinstance(node, ast.Call):
        _check_call(node, vocab, out)
    else:
        raise ExpressionError(
            f"{type(node).__name__.lower()} is not allowed in a condition", getattr(node, "col_offset", 0)
        )


def _check_call(node: ast.Call, vocab: Vocabulary, out: Condition) -> None:
    if not isinstance(node.func, ast.Name) or node.func.id not in vocab.functions:
        name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
        raise ExpressionError(f"unknown function {name!r} (known: {_known(vocab)})", node.col_offset)
    arity = vocab.functions[node.func.id]
    if node.keywords or len(node.args) != arity:
        raise ExpressionError(f"{node.func.id}() takes {arity} argument{'s' if arity != 1 else ''}", node.col_offset)
    args: list[Any] = []
    for arg in node.args:
        if not (isinstance(arg, ast.Constant) and isinstance(arg.value, (str, int, float))):
            raise ExpressionError(f"arguments of {node.func.id}() must be literal values", arg.col_offset)
        args.append(arg.value)
    out.calls.append((node.func.id, tuple(args)))


def _known(vocab: Vocabulary) -> str:
    items = [f"{name}()" for name in sorted(vocab.functions)] + sorted(vocab.names)
    if vocab.attributes:
        items.append("service.field")
    return ", ".join(items)


class Environment:
    """What a condition is evaluated against; the runtime fills it in (HFSM §5.2, switching §3.1.2.7)."""

    def __init__(
        self,
        *,
        functions: Mapping[str, Callable[..., Any]],
        names: Mapping[str, Any] | None = None,
        attributes: Callable[[str, str], Any] | None = None,
    ) -> None:
        self.functions = functions
        self.names = names or {}
        self.attributes = attributes


def evaluate(condition: Condition, env: Environment) -> Any:
    """Evaluate a parsed condition; a missing value (None) makes comparisons false."""
    return _eval(condition.tree.body, env)


def _eval(node: ast.AST, env: Environment) -> Any:
    if isinstance(node, ast.BoolOp):
        if isinstance(node.op, ast.And):
            return all(bool(_eval(v, env)) for v in node.values)
        return any(bool(_eval(v, env)) for v in node.values)
    if isinstance(node, ast.UnaryOp):
        value = _eval(node.operand, env)
        if isinstance(node.op, ast.Not):
            return not value
        return None if value is None else (-value if isinstance(node.op, ast.USub) else +value)
    if isinstance(node, ast.Compare):
        left = _eval(node.left, env)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = _eval(right_node, env)
            if left is None or right is None or not _COMPARE[type(op)](left, right):
                return False
            left = right
        return True
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.Name):
        return {"True": True, "False": False}.get(node.id, env.names.get(node.id))
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
        return env.attributes(node.value.id, node.attr) if env.attributes else None
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        args = [arg.value for arg in node.args if isinstance(arg, ast.Constant)]
        return env.functions[node.func.id](*args)
    raise ExpressionError(f"cannot evaluate {ast.unparse(node)!r}")
