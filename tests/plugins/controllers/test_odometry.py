"""diff-drive-odometry: a known arc from wheel speeds, the covariance of a straight run by hand,
the dispersion growing only while the base moves, and its Odometry message."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from plugins.controllers.odometry import DiffDriveOdometry
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.vector_records import record

DT = 0.02


def odometry(roles: tuple[str, str] = ("measure", "measure"), **params: object) -> DiffDriveOdometry:
    inputs = [("left_speed", roles[0]), ("right_speed", roles[1])]
    return DiffDriveOdometry(record("diff-drive-odometry", DT, inputs, ["/kobuki/wheel_odom"], **params))


def drive(c: DiffDriveOdometry, left: float, right: float, steps: int) -> dict[str, object]:
    message: dict[str, object] = {}
    for _ in range(steps):
        (message,) = c.step_outputs({"measure[0]": left, "measure[1]": right}, DT)
    return message


def test_integrates_a_known_arc() -> None:
    c = odometry(wheelBase=0.2)
    message = drive(c, 0.1, 0.2, 100)  # v = 0.15 m/s, ω = 0.5 rad/s: radius 0.3 m, 1 rad in 2 s
    pose = message["pose"]
    assert isinstance(pose, dict)
    assert pose["x"] == pytest.approx(0.3 * math.sin(1.0), abs=1e-4)
    assert pose["y"] == pytest.approx(0.3 * (1 - math.cos(1.0)), abs=1e-4)
    assert pose["yaw"] == pytest.approx(1.0)
    assert message["twist"] == pytest.approx({"linear": 0.15, "angular": 0.5})


def test_straight_run_covariance_by_hand() -> None:
    c = odometry(wheelBase=0.23, wheelError=1e-4)
    message = drive(c, 0.5, 0.5, 100)  # 1 m straight ahead
    assert c.covariance[0, 0] == pytest.approx(1e-4 * 1.0 / 2)  # var(Δs) = k(|Δl| + |Δr|)/4, summed
    assert c.covariance[2, 2] == pytest.approx(1e-4 * 2.0 / 0.23**2)  # var(Δθ) = k(|Δl| + |Δr|)/b²
    assert np.allclose(c.covariance, c.covariance.T) and np.all(np.linalg.eigvalsh(c.covariance) >= -1e-15)
    assert message["dispersion"] == pytest.approx(math.sqrt(c.covariance[0, 0] + c.covariance[1, 1]))


def test_dispersion_grows_with_travel_and_holds_at_rest() -> None:
    c = odometry(("left", "right"), wheelBase=0.23, wheelError=1e-4)
    dispersions = []
    for _ in range(5):
        for _ in range(50):
            (message,) = c.step_outputs({"left": 0.3, "right": 0.35}, DT)
        dispersions.append(message["dispersion"])
    assert all(b > a for a, b in itertools.pairwise(dispersions))
    for _ in range(50):
        (still,) = c.step_outputs({"left": 0.0, "right": 0.0}, DT)
    assert still["dispersion"] == pytest.approx(dispersions[-1]) and still["twist"] == {"linear": 0.0, "angular": 0.0}


def test_message_has_the_odometry_fields_and_state_round_trips() -> None:
    c = odometry(wheelBase=0.23, x=1.0, y=2.0, yaw=math.pi / 2)
    message = drive(c, 0.2, 0.2, 50)
    assert sorted(message) == ["dispersion", "pose", "stamp", "twist"]
    assert message["pose"] == pytest.approx({"x": 1.0, "y": 2.2, "yaw": math.pi / 2})
    other = odometry(wheelBase=0.23)
    other.restore(c.state())
    assert drive(other, 0.1, 0.3, 10)["pose"] == pytest.approx(drive(c, 0.1, 0.3, 10)["pose"])
    pose = message["pose"]
    assert isinstance(pose, dict) and all(isinstance(v, float) for v in pose.values())


def test_wrong_inputs_are_refused_at_build() -> None:
    with pytest.raises(ParamError, match="left and right wheel speeds"):
        DiffDriveOdometry(record("diff-drive-odometry", DT, [("s", "measure")], ["o"], wheelBase=0.2))
    with pytest.raises(ParamError, match="needs parameter 'wheelBase'"):
        odometry()
