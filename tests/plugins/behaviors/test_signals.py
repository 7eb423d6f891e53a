"""``behavior.wait-signal`` and ``behavior.emit-signal`` (issue M, point 3; D268): a value heard before
the state was entered never ends the wait (topics and plan signals), only a matching payload does, and
the payload reaches later states; emit-signal's payload carries fields from Params and from inputs."""

from __future__ import annotations

import functools
from typing import Any

import pytest

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorInput, BehaviorOutput
from plugins.behaviors.signals import EmitSignal, WaitSignal, field_of, matches
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from runtime.missions.signals import Signals


class Inputs:
    """Topic inputs as the agent gives them: the newest value and how many have arrived."""

    def __init__(self) -> None:
        self.values: dict[str, Any] = {}
        self.counts: dict[str, int] = {}

    def publish(self, name: str, value: Any) -> None:
        self.values[name] = value
        self.counts[name] = self.counts.get(name, 0) + 1

    def count(self, name: str) -> int:
        return self.counts.get(name, 0)

    def context(self, names: tuple[str, ...], written: list[tuple[str, Any]]) -> BehaviorContext:
        return BehaviorContext(
            services={}, now=lambda: 0.0,
            inputs={n: functools.partial(self.values.get, n) for n in names},
            heard={n: functools.partial(self.count, n) for n in names},
            outputs={"found": lambda value: written.append(("found", value))},
        )  # fmt: skip


def record(kind: str, inputs: tuple[str, ...] = ("spotted",), **params: str) -> BehaviorRecord:
    signal = params.pop("signal", "") == "yes"
    ports = tuple(BehaviorInput(name=n, signal=n) if signal else BehaviorInput(name=n, topic=f"/{n}") for n in inputs)
    return BehaviorRecord(name="WAIT", kind=kind, timeout=60.0, inputs=ports,
                          outputs=(BehaviorOutput(name="found", topic="/found"),),
                          params=tuple(Param(name=k, value=v) for k, v in params.items()))


def test_a_topic_value_from_before_the_state_never_ends_the_wait() -> None:
    topics, written = Inputs(), list[tuple[str, Any]]()
    topics.publish("spotted", {"label": "parcel", "x": 1.0})  # left from an earlier state
    wait = WaitSignal(record("wait-signal"), topics.context(("spotted",), written))
    wait.start()
    for _ in range(3):
        assert not wait.step().done
    topics.publish("spotted", {"label": "parcel", "x": 1.0})  # the same content, heard anew
    assert wait.step().done
    assert wait.value == {"label": "parcel", "x": 1.0} and written == [("found", {"label": "parcel", "x": 1.0})]


def test_only_a_payload_whose_field_matches_ends_the_wait() -> None:
    topics, written = Inputs(), list[tuple[str, Any]]()
    wait = WaitSignal(record("wait-signal", field="label", equals="parcel"), topics.context(("spotted",), written))
    wait.start()
    topics.publish("spotted", {"label": "box", "x": 2.0})
    status = wait.step()
    assert not status.done
    assert status.detail == "waiting for a new value on spotted with label = parcel (1 heard, none matching)"
    topics.publish("spotted", {"label": "parcel", "x": 3.0})
    assert wait.step().done and wait.value["x"] == 3.0


def test_a_dotted_field_and_a_number_compare_as_the_payload_has_them() -> None:
    assert field_of({"position": {"frame": "map"}}, "position.frame") == "map"
    assert field_of({"position": 3}, "position.frame") is None
    assert matches(2, "2.0") and matches(True, "true") and not matches("2", "two") and not matches(None, "x")
    topics, written = Inputs(), list[tuple[str, Any]]()
    wait = WaitSignal(record("wait-signal", field="count", equals="2"), topics.context(("spotted",), written))
    wait.start()
    topics.publish("spotted", {"count": 1})
    assert not wait.step().done
    topics.publish("spotted", {"count": 2})
    assert wait.step().done


def test_a_plan_signal_latched_before_entry_counts_only_with_latched() -> None:
    signals = Signals()
    signals.set("spotted", {"agent": "air", "state": "SPOT", "time": 1.0, "data": {"label": "parcel"}})

    def made(**params: str) -> WaitSignal:
        context = BehaviorContext(services={}, outputs={"found": lambda value: None}, now=lambda: 0.0,
                                  inputs={"spotted": lambda: signals.data("spotted")},
                                  heard={"spotted": lambda: signals.count("spotted")})
        wait = WaitSignal(record("wait-signal", ("spotted",), signal="yes", **params), context)
        wait.start()
        return wait

    fresh_only = made()
    assert not fresh_only.step().done  # the latched signal is from before this state
    assert made(latched="true").step().done
    fresh_only_after = made()
    signals.set("spotted", {"agent": "air", "state": "SPOT", "time": 2.0, "data": {"label": "parcel"}})
    assert fresh_only_after.step().done and fresh_only_after.value == {"label": "parcel"}


def test_without_arrival_counts_a_changed_value_is_the_new_one() -> None:
    values: dict[str, Any] = {"spotted": "old"}
    context = BehaviorContext(services={}, inputs={"spotted": lambda: values.get("spotted")}, outputs={},
                              now=lambda: 0.0)
    wait = WaitSignal(BehaviorRecord(name="W", kind="wait-signal", inputs=(BehaviorInput(name="spotted",
                                                                                         topic="/s"),)), context)
    wait.start()
    assert not wait.step().done
    values["spotted"] = "new"
    assert wait.step().done


@pytest.mark.parametrize(
    ("inputs", "params", "message"),
    [
        (("a", "b"), {}, "it waits on one input: give it one <Input> or name one with parameter 'input'"),
        (("a",), {"input": "c"}, "parameter 'input' = 'c' is not one of its inputs (['a'])"),
    ],
)
def test_an_input_that_is_not_one_is_refused(inputs: tuple[str, ...], params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=r"behavior 'WAIT' \(wait-signal\)") as caught:
        WaitSignal(record("wait-signal", inputs, **params), Inputs().context(inputs, []))
    assert message in str(caught.value)


def test_emit_signal_writes_param_fields_and_fields_taken_from_inputs_once() -> None:
    topics, written = Inputs(), list[tuple[str, Any]]()
    emit = EmitSignal(record("emit-signal", ("seen",), fields="label: red parcel; priority: 2; urgent: true",
                             take="position: seen.position; reliability: seen.reliability"),
                      topics.context(("seen",), written))
    emit.start()
    status = emit.step()
    assert not status.done and status.detail == "waiting for seen.position"
    topics.publish("seen", {"position": {"frame": "map", "x": 4.0, "y": 1.0}, "reliability": 0.8})
    assert emit.step().done and emit.step().done
    assert written == [("found", {"label": "red parcel", "priority": 2, "urgent": True, "reliability": 0.8,
                                  "position": {"frame": "map", "x": 4.0, "y": 1.0}})]


def test_emit_signal_with_fresh_takes_only_a_value_heard_after_entry() -> None:
    topics, written = Inputs(), list[tuple[str, Any]]()
    topics.publish("seen", {"x": 1.0})
    emit = EmitSignal(record("emit-signal", ("seen",), take="x: seen.x", fresh="true"),
                      topics.context(("seen",), written))
    emit.start()
    assert not emit.step().done
    topics.publish("seen", {"x": 2.0})
    assert emit.step().done and written == [("found", {"x": 2.0})]


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({}, "give its payload's fields: parameter 'fields' or 'take'"),
        ({"take": "x: other.x"}, "field 'x' takes from 'other', which is not one of its inputs (['seen'])"),
        ({"take": "x"}, "parameter 'take' entry 'x' is not 'name: values'"),
    ],
)
def test_emit_signal_refuses_a_payload_it_cannot_build(params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError) as caught:
        EmitSignal(record("emit-signal", ("seen",), **params), Inputs().context(("seen",), []))
    assert message in str(caught.value)
