"""Conditions are parsed once, when their record is built: <Transition when> and <Switch when>
carry the parsed Condition, a condition that does not parse keeps its error, and every located
problem goes through ConfigError.of (issue H point 4)."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

import ckmconf
from ckmconf.errors import ConfigError, Loc, located
from ckmconf.expressions import ExpressionError
from ckmconf.model import Switch, Transition
from tests.conftest import REPO


def test_a_transition_carries_its_parsed_condition() -> None:
    transition = Transition(from_="a", to="b", when="done() and arm.progress > 0.5 or signal('go')")
    assert transition.condition_error is None
    assert transition.condition is transition.condition  # parsed once, not at each use
    assert transition.condition.calls == [("done", ()), ("signal", ("go",))]
    assert transition.condition.attributes == [("arm", "progress")]
    assert Transition(from_="a", to="b").condition.calls == [("done", ())]  # the default, done()


def test_a_switch_uses_the_switch_vocabulary() -> None:
    switch = Switch(to="safe", when="alarm('hot') or stale('/speed') and elapsed > 1")
    assert switch.condition.calls == [("alarm", ("hot",)), ("stale", ("/speed",))]
    assert switch.condition.names == ["elapsed"]
    refused = Switch(to="safe", when="done()")  # a transition's function, not a switch's
    assert isinstance(refused.condition_error, ExpressionError)
    assert "unknown function 'done'" in str(refused.condition_error)


def test_a_condition_that_does_not_parse_is_kept_as_its_error_and_raised_located() -> None:
    loc = Loc("robot.xml", 12, 7, "/System/Node[@name='n']/Controller[@name='c']/Switch")
    switch = Switch(to="safe", when="alarm('hot'", loc=loc)
    error = switch.condition_error
    assert error is not None and "syntax error" in str(error)
    with pytest.raises(ConfigError) as caught:
        _ = switch.condition
    assert (caught.value.file, caught.value.line, caught.value.column) == ("robot.xml", 12, 7)
    assert caught.value.xpath == loc.xpath + "/@when"


def test_the_parsed_condition_is_not_part_of_equality_and_survives_copies() -> None:
    first = Transition(from_="a", to="b", when="failed()")
    second = Transition(from_="a", to="b", when="failed()")
    assert first == second and hash(first) == hash(second)
    assert pickle.loads(pickle.dumps(first)).condition.calls == [("failed", ())]
    changed = dataclasses.replace(first, when="timeout()")
    assert changed.condition.calls == [("timeout", ())]  # re-parsed for the new text


def test_loaded_records_carry_parsed_conditions() -> None:
    system = ckmconf.load(REPO / "configs" / "examples" / "controller_switching.xml")
    switches = [sw for node in system.nodes for c in node.controllers for sw in c.switches]
    assert switches and all(sw.condition_error is None for sw in switches)
    assert ("stale", ("/wheel/load",)) in [call for sw in switches for call in sw.condition.calls]


def test_a_bad_condition_is_found_at_load_at_its_character() -> None:
    path = REPO / "configs" / "invalid" / "controller_bad_switch_condition.xml"
    result = ckmconf.load(path, strict=False)
    assert [(e.line, e.column) for e in result.errors if "overheat" in e.message] == [(16, 49)]


def test_config_error_of_a_record_with_and_without_its_location() -> None:
    loc = Loc("a.xml", 3, 5, "/System/Topic")
    transition = Transition(from_="x", to="y", loc=loc)
    assert str(ConfigError.of(transition, "bad")) == "a.xml:3:5: /System/Topic: bad"
    assert ConfigError.of(transition, "bad", "to").xpath == "/System/Topic/@to"
    built = Transition(from_="x", to="y")  # built in code: no file
    assert str(ConfigError.of(built, "bad")) == "<memory>:1:1: /Transition: bad"
    assert located(built) == Loc("<memory>", 1, 1, "/Transition")
