"""``hardware.sim`` Param ``initial``: an out channel's joint stands at a given raw value when the robot
is spawned (the use case's arm is powered on folded, out of the Xtion's view) and stays there."""

from __future__ import annotations

import pytest

from plugins.hardware.simulation import ManualClock, PlantScope
from runtime.kernel.interfaces import ParamError
from tests.plugins.sim.test_backend import channel, open_all

SCALE, OFFSET = 0.0051183, 511.5  # AX-12 steps, as configs/usecase/nodes.xml


def test_an_initial_value_places_and_holds_the_joint() -> None:
    clock = ManualClock()
    scope = PlantScope(clock, name="initial-test")
    elbow, state = open_all(
        scope,
        channel("elbow", "out", "bus", joint="arm_elbow_flex_joint", mode="position", scale=str(SCALE),
                offset=str(OFFSET), initial="899", body="turtlebot", pose="1 1 0"),
        channel("state", "in", "bus", size=1, joints="arm_elbow_flex_joint", body="turtlebot",
                scale=str(SCALE), offset=str(OFFSET)),
    )
    assert state.read()[0] == pytest.approx(899, abs=3)  # type: ignore[index]  # placed before any physics
    clock.advance(1.0)
    assert state.read()[0] == pytest.approx(899, abs=5)  # type: ignore[index]  # held by the joint's motor
    elbow.write(511.5)
    clock.advance(2.0)
    assert state.read()[0] == pytest.approx(511.5, abs=10)  # type: ignore[index]  # and commanded as usual


@pytest.mark.parametrize(
    ("direction", "params", "message"),
    [
        ("in", {"joint": "arm_elbow_flex_joint"}, "only for an out channel"),
        ("out", {"joint": "arm_elbow_flex_joint", "mode": "velocity"}, "only for an out channel in mode 'position'"),
        ("out", {"joint": "arm_elbow_flex_joint"}, "'initial' is 'folded', not a number"),
    ],
)
def test_a_bad_initial_is_refused_naming_the_channel(direction: str, params: dict[str, str], message: str) -> None:
    initial = "folded" if "not a number" in message else "899"
    with pytest.raises(ParamError, match=message) as caught:
        open_all(PlantScope(ManualClock(), name="initial-bad"),
                 channel("elbow", direction, "bus", 1, body="turtlebot", initial=initial, **params))
    assert "sim channel 'elbow'" in str(caught.value)
