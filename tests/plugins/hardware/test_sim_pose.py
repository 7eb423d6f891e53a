"""The ``hardware.sim`` ground-truth pose channel (``sensor="pose"``): the true planar pose of a
robot's link in the map, for reports and benchmarks (what the estimate is compared with)."""

from __future__ import annotations

import math

import pytest

from plugins.hardware.simulation import ManualClock, PlantScope
from runtime.kernel.interfaces import ParamError
from tests.plugins.sim.test_backend import channel, open_all


def test_the_pose_channel_follows_the_robot_exactly() -> None:
    clock = ManualClock()
    scope = PlantScope(clock, name="pose-test")
    left, right, truth = open_all(
        scope,
        channel("l", "out", "pwm", joint="left_wheel_joint", mode="velocity", maxVelocity="8", body="rover",
                pose="3.0 2.0 0.5"),
        channel("r", "out", "pwm", joint="right_wheel_joint", mode="velocity", maxVelocity="8", body="rover"),
        channel("t", "in", "bus", size=3, body="rover", sensor="pose"),
    )
    x0, y0, yaw0 = truth.read()  # type: ignore[misc]  # a vector channel reads a tuple
    assert (x0, y0) == pytest.approx((3.0, 2.0), abs=0.02) and yaw0 == pytest.approx(0.5, abs=0.02)
    for backend in (left, right):
        backend.write(0.5)  # both wheels forward: a straight line along the heading
    clock.advance(2.0)
    x1, y1, yaw1 = truth.read()  # type: ignore[misc]
    travelled = math.hypot(x1 - x0, y1 - y0)
    assert travelled > 0.2
    assert math.atan2(y1 - y0, x1 - x0) == pytest.approx(0.5, abs=0.1) and yaw1 == pytest.approx(0.5, abs=0.1)


def test_a_pose_channel_must_hold_three_values() -> None:
    with pytest.raises(ParamError, match="size is 2, its pose device gives 3 values"):
        open_all(PlantScope(ManualClock(), name="pose-bad"), channel("t", "in", "bus", size=2, body="rover",
                                                                     sensor="pose"))
