"""friction-feedforward: the feed-forward by hand, the integrator left with only what the friction
model misses on a plant with Coulomb friction, bumpless take-over, limits and its Params."""

from __future__ import annotations

import pytest

from plugins.controllers.feedforward import FrictionFeedforward
from plugins.lti import PlantModel, Vector
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.records import controller_record

DT = 0.01
MOTOR = PlantModel(order=1, gain=1.0, time_constant=0.2)
FRICTION = 0.2  # Coulomb friction of the plant, in units of its input


def feedforward(**params: object) -> FrictionFeedforward:
    return FrictionFeedforward(controller_record("friction-feedforward", DT, 10, **params))


def test_feedforward_by_hand() -> None:
    c = feedforward(kp=1.0, coulomb=0.1, viscous=0.2)
    assert c.step({"measure": 0.3, "setpoint": 0.5}, DT) == pytest.approx(0.2 + 0.1 + 0.1)
    assert c.step({"measure": 0.0, "setpoint": -0.5}, DT) == pytest.approx(-0.5 - 0.1 - 0.1)
    c = feedforward(kp=0.0, coulomb=0.1, deadband=0.01)
    assert c.step({"measure": 0.0, "setpoint": 0.005}, DT) == pytest.approx(0.05)  # inside the dead band
    assert c.step({"measure": 0.0, "setpoint": 0.0}, DT) == 0.0


def run(c: FrictionFeedforward, steps: int, setpoint: float) -> float:
    x: Vector = (0.0,)
    for _ in range(steps):
        u = c.step({"measure": x[0], "setpoint": setpoint}, DT)
        friction = FRICTION if x[0] > 1e-6 or u > FRICTION else 0.0  # sticks until u exceeds it
        x = MOTOR.advance(x, max(0.0, u - friction) if u >= 0 else u + FRICTION, DT)
    return x[0]


def test_the_integrator_supplies_only_what_the_friction_model_misses() -> None:
    with_model, without = feedforward(kp=1.0, ki=5.0, coulomb=FRICTION), feedforward(kp=1.0, ki=5.0)
    assert run(with_model, 1500, 0.5) == pytest.approx(0.5, abs=1e-3)
    assert run(without, 1500, 0.5) == pytest.approx(0.5, abs=1e-3)
    assert with_model.state()["integral"] == pytest.approx(0.5, abs=1e-3)  # u = y/gain, the friction fed forward
    assert without.state()["integral"] == pytest.approx(0.5 + FRICTION, abs=1e-3)


def test_feedforward_speeds_up_the_response() -> None:
    early = [run(feedforward(kp=1.0, ki=5.0, coulomb=c), 60, 0.5) for c in (FRICTION, 0.0)]
    assert abs(0.5 - early[0]) < abs(0.5 - early[1])


def test_bumpless_take_over_and_output_limits() -> None:
    c = feedforward(kp=1.0, ki=2.0, coulomb=0.1, outputLimit=0.7)
    c.bumpless(0.42)
    assert c.step({"measure": 0.3, "setpoint": 0.5}, DT) == pytest.approx(0.42)
    assert c.step({"measure": -5.0, "setpoint": 0.5}, DT) == pytest.approx(0.7)
    assert c.future() == [pytest.approx(0.7)] * 10
    other = feedforward(kp=1.0, ki=2.0, coulomb=0.1, outputLimit=0.7)
    other.restore(c.state())
    assert other.step({"measure": 0.4, "setpoint": 0.5}, DT) == c.step({"measure": 0.4, "setpoint": 0.5}, DT)
    with pytest.raises(ValueError, match="not a friction-feedforward controller state"):
        other.restore({**c.state(), "kind": "pid"})


def test_param_errors() -> None:
    with pytest.raises(ParamError, match=r"'coulomb' = -1\.0 must not be negative"):
        feedforward(coulomb=-1)
    with pytest.raises(ParamError, match=r"takes no parameter 'gain' \(accepted: .*coulomb"):
        feedforward(gain=1)
