"""Find values of a state's condition variables that make one transition the one that fires.

The "fake interaction" of §7.5.1 must force every transition. A state's transitions are tried
in document order (D14), so transition k fires when its condition holds and every earlier one
does not. The variables of a condition are its calls (``done()``, ``timeout()``, ``outcome('x')``,
``signal('s')``), its names (``progress``, ``elapsed``, ``performance``) and its service fields
(``alias.field``). Each gets a few candidate values — booleans, and for a numeric variable each
constant it is compared with, just below, at and just above — and the candidates are searched,
fewest raised flags first, with the conditions evaluated by ckmconf's own evaluator. Facts the
driver cannot choose (a nested mission's outcome, whether it has ended) are fixed.
"""

from __future__ import annotations

import ast
import itertools
from collections.abc import Mapping, Sequence
from typing import Any

from ckmconf.expressions import Condition, Environment, evaluate

Key = tuple[Any, ...]
"""("call", name, *args) | ("name", name) | ("attr", alias, field)"""

DELTA = 0.01
MAX_COMBINATIONS = 20000


def _keys(node: ast.AST, out: dict[Key, set[Any]], bare: set[Key]) -> None:
    """Collect the variables of a condition and the constants they are compared with."""
    if isinstance(node, ast.Compare):
        operands = [node.left, *node.comparators]
        constants = [o.value for o in operands if isinstance(o, ast.Constant)]
        for operand in operands:
            key = _key(operand)
            if key is not None:
                out.setdefault(key, set()).update(c for c in constants if not isinstance(c, str))
        for operand in operands:
            if _key(operand) is None:
                _keys(operand, out, bare)
        return
    key = _key(node)
    if key is not None:
        out.setdefault(key, set())
        bare.add(key)
        return
    for child in ast.iter_child_nodes(node):
        _keys(child, out, bare)


def _key(node: ast.AST) -> Key | None:
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        return ("call", node.func.id, *(a.value for a in node.args if isinstance(a, ast.Constant)))
    if isinstance(node, ast.Name) and node.id not in ("True", "False"):
        return ("name", node.id)
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
        return ("attr", node.value.id, node.attr)
    return None


def _candidates(key: Key, constants: set[Any], bare: bool) -> list[Any]:
    if key[0] == "call":
        return [False, True]
    values: list[Any] = [False, True] if bare else []
    for c in sorted(c for c in constants if isinstance(c, int | float) and not isinstance(c, bool)):
        values += [c - DELTA * max(1.0, abs(c)), c, c + DELTA * max(1.0, abs(c))]
    return values or [0.0]


def environment(values: Mapping[Key, Any]) -> Environment:
    """An Environment answering from ``values`` (unknown variables: False / None)."""
    return Environment(
        functions={
            name: (lambda *args, n=name: bool(values.get(("call", n, *args), False)))
            for name in ("done", "failed", "timeout", "outcome", "signal", "lost")
        },
        names={k[1]: v for k, v in values.items() if k[0] == "name"},
        attributes=lambda alias, field: values.get(("attr", alias, field)),
    )


def _cost(values: Mapping[Key, Any]) -> int:
    return sum(1 for k, v in values.items() if k[0] == "call" and v is True)


def solve(conditions: Sequence[Condition], target: int, fixed: Mapping[Key, Any]) -> dict[Key, Any] | None:
    """Values making ``conditions[target]`` the first that holds, or None when none exist."""
    variables: dict[Key, set[Any]] = {}
    bare: set[Key] = set()
    for condition in conditions[: target + 1]:
        _keys(condition.tree.body, variables, bare)
    free = [k for k in variables if k not in fixed]
    domains = [_candidates(k, variables[k], k in bare) for k in free]
    best: dict[Key, Any] | None = None
    for count, combination in enumerate(itertools.product(*domains)):
        if count >= MAX_COMBINATIONS:
            break
        values = {**dict(zip(free, combination, strict=True)), **fixed}
        if best is not None and _cost(values) >= _cost(best):
            continue
        env = environment(values)
        if evaluate(conditions[target], env) and not any(evaluate(c, env) for c in conditions[:target]):
            best = values
            if _cost(best) <= 1:
                break
    return best
