"""controller.twist-axes: a Twist split into one set point per axis, bounded and ramped."""

from __future__ import annotations

import math

import pytest

from plugins.controllers.axes import TwistAxes
from runtime.kernel.interfaces import ParamError

from .vector_records import record

QUAD = "linear.x linear.y linear.z angular.z"


def axes(outputs: int = 4, **params: object) -> TwistAxes:
    given = {"axes": QUAD, **params}
    return TwistAxes(record("twist-axes", 0.02, [("/cmd_vel", "setpoint")], [f"/a{i}" for i in range(outputs)],
                            **given))


def twist(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> dict[str, object]:
    return {"linear": {"x": x, "y": y, "z": z}, "angular": {"x": 0.0, "y": 0.0, "z": yaw}}


def test_each_output_carries_its_axis_in_the_order_named() -> None:
    controller = axes()
    assert controller.step_outputs({"setpoint": twist(0.3, -0.2, 0.5, 0.1)}, 0.02) == (0.3, -0.2, 0.5, 0.1)
    reordered = axes(2, axes="angular.z linear.z")
    assert reordered.step_outputs({"setpoint": twist(0.3, -0.2, 0.5, 0.1)}, 0.02) == (0.1, 0.5)


def test_a_planar_twist_drives_a_holonomic_base_and_its_missing_axes_are_zero() -> None:
    controller = axes(3, axes="linear.x linear.y angular.z")
    assert controller.step_outputs({"setpoint": {"linear": 0.4, "angular": -0.3}}, 0.02) == (0.4, 0.0, -0.3)


def test_the_linear_speed_is_bounded_along_its_direction_and_the_turn_clamped() -> None:
    controller = axes(maxLinear=1.0, maxAngular=0.5)
    vx, vy, vz, wz = controller.step_outputs({"setpoint": twist(3.0, 4.0, 0.0, 2.0)}, 0.02)
    assert math.hypot(vx, vy, vz) == pytest.approx(1.0)
    assert vy / vx == pytest.approx(4.0 / 3.0)  # the direction is kept
    assert wz == 0.5


def test_set_points_ramp_at_the_acceleration_limit_and_a_lost_command_ramps_to_hover() -> None:
    controller = axes(maxAcceleration=1.0, maxAngularAcceleration=2.0)
    first = controller.step_outputs({"setpoint": twist(1.0, 0.0, 0.0, 1.0)}, 0.1)
    assert first == pytest.approx((0.1, 0.0, 0.0, 0.2))
    for _ in range(20):
        controller.step_outputs({"setpoint": twist(1.0, 0.0, 0.0, 1.0)}, 0.1)
    assert controller.step_outputs({}, 0.1) == pytest.approx((0.9, 0.0, 0.0, 0.8))
    assert [row[0] for row in controller.future_outputs()][:3] == pytest.approx([0.88, 0.86, 0.84])
    state = controller.state()
    again = axes(maxAcceleration=1.0, maxAngularAcceleration=2.0)
    again.restore(state)
    assert again.step_outputs({}, 0.1) == pytest.approx((0.8, 0.0, 0.0, 0.6))


@pytest.mark.parametrize(
    ("outputs", "given", "message"),
    [
        (4, "linear.x linear.q linear.z angular.z", "(not linear.q)"),
        (4, "linear.x linear.x linear.z angular.z", "distinct Twist fields"),
        (3, QUAD, "names 4 axes but the controller has 3 Outputs"),
    ],
)
def test_bad_axes_are_refused_naming_the_controller(outputs: int, given: str, message: str) -> None:
    with pytest.raises(ParamError, match="controller 'twist-axes'") as error:
        axes(outputs, axes=given)
    assert message in str(error.value)


@pytest.mark.parametrize("bad", [twist(math.nan), {"linear": {"x": "fast"}}, {"linear": [1, 2]}])
def test_a_bad_command_is_an_error_naming_the_axis(bad: dict[str, object]) -> None:
    with pytest.raises((ValueError, TypeError), match="velocity command"):
        axes().step_outputs({"setpoint": bad}, 0.02)
