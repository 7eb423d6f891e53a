"""pan-tilt-position: converging on a first-order head servo, the speed bound, the angle limits,
a target given in the image, and the lead bound when the head is blocked."""

from __future__ import annotations

import math

import pytest

from plugins.controllers.pantilt import PanTiltPosition
from plugins.lti import PlantModel, Vector
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.vector_records import record

DT = 0.02
SERVO = PlantModel(order=1, gain=1.0, time_constant=0.05)  # a position servo: command → angle
NAO = {"panMin": -2.0857, "panMax": 2.0857, "tiltMin": -0.6720, "tiltMax": 0.5149}


def head(**params: object) -> PanTiltPosition:
    inputs = [("/nao/head_goal", "setpoint"), ("head_yaw_angle", "measure"), ("head_pitch_angle", "measure")]
    return PanTiltPosition(record("pan-tilt-position", DT, inputs, ["head_yaw_cmd", "head_pitch_cmd"], **params))


class Head:
    """The controller closing the loop on two servo plants, stepped with a fixed dt."""

    def __init__(self, controller: PanTiltPosition) -> None:
        self.controller = controller
        self.x: list[Vector] = [(0.0,), (0.0,)]
        self.commands: list[tuple[float, ...]] = []

    @property
    def angles(self) -> tuple[float, float]:
        return self.x[0][0], self.x[1][0]

    def run(self, steps: int, goal: dict[str, float] | None, blocked: bool = False) -> None:
        for _ in range(steps):
            inputs: dict[str, object] = {"measure[0]": self.angles[0], "measure[1]": self.angles[1]}
            if goal is not None:
                inputs["setpoint"] = goal
            command = self.controller.step_outputs(inputs, DT)
            self.commands.append(command)
            if not blocked:
                self.x = [SERVO.advance(x, u, DT) for x, u in zip(self.x, command, strict=True)]


def test_converges_on_the_goal_within_the_speed_bound() -> None:
    loop = Head(head(kp=4.0, maxSpeed=2.0, **NAO))
    loop.run(150, {"pan": 1.0, "tilt": 0.3})
    assert loop.angles == pytest.approx((1.0, 0.3), abs=1e-3)
    steps = [abs(b[0] - a[0]) for a, b in zip(loop.commands, loop.commands[1:], strict=False)]
    assert max(steps) <= 2.0 * DT + 1e-12


def test_goals_beyond_the_limits_stop_at_the_limits() -> None:
    loop = Head(head(kp=4.0, maxSpeed=2.0, **NAO))
    loop.run(200, {"pan": -3.0, "tilt": 1.0})
    assert all(-2.0857 <= p <= 2.0857 and -0.6720 <= t <= 0.5149 for p, t in loop.commands)
    assert loop.angles == pytest.approx((-2.0857, 0.5149), abs=1e-3)


def test_target_in_the_image_turns_toward_it() -> None:
    # A target at column 480 of a 640-px image with a 90° field of view lies atan(160/320) to the right.
    loop = Head(head(target="image", imageWidth=640, imageHeight=480, fov=math.pi / 2, maxSpeed=2.0))
    loop.run(150, {"pan": 480.0, "tilt": 240.0 + 320.0 * math.tan(0.2)})  # and 0.2 rad below the centre
    assert loop.angles == pytest.approx((-math.atan(0.5), 0.2), abs=1e-3)
    loop.run(50, {"pan": 480.0, "tilt": 240.0 + 320.0 * math.tan(0.2)})  # the same (held) target: no new goal
    assert loop.angles == pytest.approx((-math.atan(0.5), 0.2), abs=1e-3)


def test_a_blocked_head_keeps_the_reference_within_the_lead() -> None:
    loop = Head(head(maxSpeed=2.0, maxLead=0.3))
    loop.run(100, {"pan": 1.5, "tilt": 0.0}, blocked=True)
    assert loop.commands[-1][0] == pytest.approx(0.3)
    loop.run(300, {"pan": 1.5, "tilt": 0.0})
    assert loop.angles[0] == pytest.approx(1.5, abs=1e-3)


def test_holds_without_a_goal_and_continues_in_the_future() -> None:
    c = head(kp=4.0, maxSpeed=1.0)
    assert c.step_outputs({"measure[0]": 0.2, "measure[1]": -0.1}, DT) == pytest.approx((0.2, -0.1))
    moved = c.step_outputs({"measure[0]": 0.2, "measure[1]": -0.1, "setpoint": {"pan": 1.2, "tilt": -0.1}}, DT)
    assert moved == pytest.approx((0.22, -0.1))  # at maxSpeed: kp·1.0 rad = 4 rad/s is above it
    future = c.future_outputs()
    assert len(future) == 10 and future[0][0] == pytest.approx(0.24) and future[-1] == pytest.approx((0.42, -0.1))


def test_bad_params_and_inputs() -> None:
    with pytest.raises(ParamError, match=r"'panMin' = 1\.0 must be less than 'panMax'"):
        head(panMin=1.0, panMax=0.5)
    with pytest.raises(ParamError, match="measured pan and tilt"):
        PanTiltPosition(record("pan-tilt-position", DT, [("g", "setpoint")], ["a", "b"]))
    with pytest.raises(TypeError, match="field 'tilt'"):
        head().step_outputs({"measure[0]": 0.0, "measure[1]": 0.0, "setpoint": {"pan": 0.1}}, DT)
