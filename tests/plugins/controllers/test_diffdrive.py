"""diff-drive and ramp-stop: inverse kinematics by hand, limits, the acceleration bound, the stop's
deceleration bound and curvature, bumpless take-over, and a base driven by both on wheel plants."""

from __future__ import annotations

import itertools
import math

import pytest

from plugins.controllers.diffdrive import DiffDrive, RampStop
from plugins.lti import PlantModel, Vector
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.vector_records import record

DT = 0.02
WHEELS = [("left_speed", "measure"), ("right_speed", "measure")]
SETPOINTS = ["left_setpoint", "right_setpoint"]


def diff_drive(**params: object) -> DiffDrive:
    return DiffDrive(record("diff-drive", DT, [("/kobuki/cmd_vel", "setpoint")], SETPOINTS, **params))


def ramp_stop(deceleration: float = 1.0, horizon: int = 10) -> RampStop:
    return RampStop(record("ramp-stop", DT, WHEELS, SETPOINTS, horizon, deceleration=deceleration))


def test_inverse_kinematics_by_hand() -> None:
    c = diff_drive(wheelBase=0.23)
    left, right = c.step_outputs({"setpoint": {"linear": 0.2, "angular": 1.0}}, DT)
    assert (left, right) == pytest.approx((0.2 - 0.115, 0.2 + 0.115))
    assert c.step_outputs({"setpoint": (0.0, -2.0)}, DT) == pytest.approx((0.23, -0.23))  # turning on the spot
    assert c.step_outputs({}, DT) == (0.0, 0.0)  # no command: stand still


def test_angular_output_divides_by_the_wheel_radius() -> None:
    c = diff_drive(wheelBase=0.23, wheelRadius=0.035, output="angular")
    assert c.step_outputs({"setpoint": {"linear": 0.35, "angular": 0.0}}, DT) == pytest.approx((10.0, 10.0))


def test_limits_bound_the_command_and_keep_the_curvature() -> None:
    c = diff_drive(wheelBase=0.2, maxLinear=0.7, maxAngular=3.14)
    assert c.step_outputs({"setpoint": {"linear": 2.0, "angular": 0.0}}, DT) == pytest.approx((0.7, 0.7))
    assert c.step_outputs({"setpoint": {"linear": 0.0, "angular": 10.0}}, DT) == pytest.approx((-0.314, 0.314))
    c = diff_drive(wheelBase=0.2, maxWheelSpeed=0.5)
    left, right = c.step_outputs({"setpoint": {"linear": 0.6, "angular": 2.0}}, DT)  # wheels 0.4 and 0.8
    assert right == pytest.approx(0.5) and left == pytest.approx(0.25)  # both scaled by 0.5/0.8: same arc


def test_acceleration_bound_and_future_ramp() -> None:
    c = diff_drive(wheelBase=0.23, maxAcceleration=1.0)
    outputs = [c.step_outputs({"setpoint": {"linear": 0.5, "angular": 0.0}}, DT) for _ in range(30)]
    steps = [b[0] - a[0] for a, b in zip([(0.0, 0.0), *outputs], outputs, strict=False)]
    assert max(steps) == pytest.approx(1.0 * DT) and outputs[-1] == pytest.approx((0.5, 0.5))
    assert outputs[9] == pytest.approx((0.2, 0.2))
    c = diff_drive(wheelBase=0.23, maxAcceleration=1.0)
    c.step_outputs({"setpoint": {"linear": 0.1, "angular": 0.0}}, DT)
    future = c.future_outputs()
    assert len(future) == 10 and future[0] == pytest.approx((0.04, 0.04)) and future[-1] == pytest.approx((0.1, 0.1))


def test_bad_commands_and_params_are_named() -> None:
    with pytest.raises(TypeError, match="field 'angular'"):
        diff_drive(wheelBase=0.23).step_outputs({"setpoint": {"linear": 0.2}}, DT)
    with pytest.raises(ParamError, match="needs parameter 'wheelBase'"):
        diff_drive()
    with pytest.raises(ParamError, match="'wheelRadius'"):
        diff_drive(wheelBase=0.2, output="angular")
    with pytest.raises(ParamError, match="writes 2 outputs"):
        DiffDrive(record("diff-drive", DT, [("c", "setpoint")], ["l"], wheelBase=0.2))


def test_a_multi_output_controller_refuses_to_write_one_value_onto_all_outputs() -> None:
    with pytest.raises(TypeError, match="step_outputs"):
        diff_drive(wheelBase=0.23).step({}, DT)


def test_ramp_stop_respects_the_deceleration_bound_and_keeps_the_arc() -> None:
    c = ramp_stop(deceleration=1.0)
    c.bumpless((0.3, 0.6))  # taking over from diff-drive's last set points
    rows = [c.step_outputs({"measure[0]": 0.3, "measure[1]": 0.6}, DT) for _ in range(40)]
    previous = (0.3, 0.6)
    for row in rows:
        assert abs(previous[1]) - abs(row[1]) <= 1.0 * DT + 1e-12  # the faster wheel at the bound
        assert row[0] == pytest.approx(row[1] / 2)  # the ratio, so the curvature, is kept
        previous = row
    assert rows[9][1] == pytest.approx(0.4) and rows[29] == (0.0, 0.0) and rows[-1] == (0.0, 0.0)


def test_ramp_stop_starts_from_the_measures_without_a_previous_output() -> None:
    c = ramp_stop(deceleration=2.0, horizon=5)
    assert c.step_outputs({"measure[0]": -0.5, "measure[1]": 0.5}, DT) == pytest.approx((-0.46, 0.46))
    assert c.future_outputs()[0] == pytest.approx((-0.42, 0.42)) and len(c.future_outputs()) == 5
    state = c.state()
    other = ramp_stop(deceleration=2.0)
    other.restore(state)
    assert other.step_outputs({}, DT) == c.step_outputs({}, DT)
    with pytest.raises(ParamError, match="one 'measure' input per output"):
        RampStop(record("ramp-stop", DT, [("a", "measure")], SETPOINTS, deceleration=1.0))


MOTOR = PlantModel(order=1, gain=1.0, time_constant=0.1)  # a speed-controlled wheel: set point → rim speed


def test_drive_then_stop_on_two_wheel_plants() -> None:
    """diff-drive drives a turn, then ramp-stop brings the real (lagging) wheels to rest bumplessly."""
    drive, stop = diff_drive(wheelBase=0.23, maxAcceleration=1.0), ramp_stop(deceleration=1.0)
    wheels: list[Vector] = [(0.0,), (0.0,)]
    setpoints: tuple[float, ...] = (0.0, 0.0)
    for _ in range(100):
        setpoints = drive.step_outputs({"setpoint": {"linear": 0.3, "angular": 1.0}}, DT)
        wheels = [MOTOR.advance(x, u, DT) for x, u in zip(wheels, setpoints, strict=True)]
    assert wheels[0][0] == pytest.approx(0.185, abs=1e-3) and wheels[1][0] == pytest.approx(0.415, abs=1e-3)
    stop.bumpless(setpoints)
    speeds = []
    for _ in range(60):
        measures = {"measure[0]": wheels[0][0], "measure[1]": wheels[1][0]}
        setpoints = stop.step_outputs(measures, DT)
        wheels = [MOTOR.advance(x, u, DT) for x, u in zip(wheels, setpoints, strict=True)]
        speeds.append(wheels[1][0])
    decelerations = [(a - b) / DT for a, b in itertools.pairwise(speeds)]
    assert max(decelerations) <= 1.0 + 1e-9 and math.isclose(setpoints[1], 0.0)
    assert abs(speeds[-1]) < 0.01
