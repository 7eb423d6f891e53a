"""The condition language: what parses, what is refused, how it evaluates."""

from __future__ import annotations

from typing import Any

import pytest

from ckmconf.expressions import SWITCH, TRANSITION, Environment, ExpressionError, evaluate, parse


def env(**names: Any) -> Environment:
    return Environment(
        functions={
            "done": lambda: names.get("_done", False),
            "failed": lambda: False,
            "timeout": lambda: names.get("_timeout", False),
            "outcome": lambda name: names.get("_outcome") == name,
            "signal": lambda name: name in names.get("_signals", ()),
        },
        names={k: v for k, v in names.items() if not k.startswith("_")},
        attributes=lambda alias, field: names.get(f"{alias}.{field}"),
    )


def test_references_are_collected() -> None:
    condition = parse("done() and rgb.reliability > 0.8 or signal('spotted') and progress >= 1", TRANSITION)
    assert condition.calls == [("done", ()), ("signal", ("spotted",))]
    assert condition.attributes == [("rgb", "reliability")]
    assert condition.names == ["progress"]


@pytest.mark.parametrize(
    "text,values,expected",
    [
        ("done()", {"_done": True}, True),
        ("not done()", {"_done": True}, False),
        ("progress >= 0.5", {"progress": 0.7}, True),
        ("0.2 < progress < 0.5", {"progress": 0.7}, False),
        ("rgb.reliability > 0.8", {"rgb.reliability": 0.9}, True),
        ("rgb.reliability > 0.8", {}, False),  # a value not yet received never satisfies a comparison
        ("outcome('arrived') or timeout()", {"_outcome": "arrived"}, True),
        ("signal('object_spotted')", {"_signals": {"object_spotted"}}, True),
        ("elapsed > 3 and -progress < 0", {"elapsed": 4.0, "progress": 0.1}, True),
    ],
)
def test_evaluation(text: str, values: dict[str, Any], expected: bool) -> None:
    assert evaluate(parse(text, TRANSITION), env(**values)) is expected


@pytest.mark.parametrize(
    "text,message",
    [
        ("done(", "syntax error in condition 'done(': '(' was never closed"),
        (
            "__import__('os')",
            "unknown function '__import__' (known: done(), failed(), lost(), outcome(), signal(), timeout(), "
            "elapsed, performance, progress, service.field)",
        ),
        ("().__class__", "attribute is not allowed in a condition"),
        ("progress[0]", "subscript is not allowed in a condition"),
        ("lambda: 1", "lambda is not allowed in a condition"),
        ("outcome()", "outcome() takes 1 argument"),
        ("signal(x)", "arguments of signal() must be literal values"),
        (
            "speed > 1",
            "unknown name 'speed' (known: done(), failed(), lost(), outcome(), signal(), timeout(), elapsed, "
            "performance, progress, service.field)",
        ),
        ("1 in progress", "only ==, !=, <, <=, >, >= comparisons are allowed"),
        ("(" * 300 + "1" + ")" * 300, "syntax error in condition"),
    ],
)
def test_refused(text: str, message: str) -> None:
    with pytest.raises(ExpressionError) as caught:
        parse(text, TRANSITION)
    assert str(caught.value).startswith(message)


def test_switch_vocabulary_has_no_service_attributes() -> None:
    parse("alarm('cpu_high') or value('/speed') > 2", SWITCH)
    with pytest.raises(ExpressionError):
        parse("rgb.reliability > 1", SWITCH)
