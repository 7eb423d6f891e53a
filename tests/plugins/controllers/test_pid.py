"""The PID: hand-computed steps, closing a loop on a first-order plant, anti-windup, bumpless
transfer, state round-trip and Param errors."""

from __future__ import annotations

import math

import msgpack
import pytest

from plugins.controllers.pid import PID
from plugins.lti import PlantModel, Vector
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.records import controller_record

DT = 0.01
PLANT = PlantModel(order=1, gain=2.0, time_constant=0.2)  # a first-order motor like the loopback plant


def pid(horizon: int = 10, /, **params: object) -> PID:
    return PID(controller_record("pid", DT, horizon, **params))


class Loop:
    """A PID closing a loop on PLANT, stepped with a fixed dt (no sleeping)."""

    def __init__(self, controller: PID, y: float = 0.0) -> None:
        self.controller = controller
        self.x: Vector = (y,)
        self.outputs: list[float] = []

    @property
    def y(self) -> float:
        return self.x[0]

    def run(self, steps: int, setpoint: float) -> None:
        for _ in range(steps):
            u = self.controller.step({"measure": self.y, "setpoint": setpoint}, DT)
            self.outputs.append(u)
            self.x = PLANT.advance(self.x, u, DT)


def test_first_steps_by_hand() -> None:
    c = pid(kp=2.0, ki=1.0, kd=0.5)
    assert c.step({"measure": 0.0, "setpoint": 1.0}, 0.1) == pytest.approx(2.0 + 0.1)  # P + I, no derivative yet
    # e = 0.5: P = 1; I = 0.1 + 0.05; D = −0.5·(0.5 − 0)/0.1 = −2.5 (derivative on measurement)
    assert c.step({"measure": 0.5, "setpoint": 1.0}, 0.1) == pytest.approx(1.0 + 0.15 - 2.5)


def test_derivative_filter() -> None:
    c = pid(kp=0.0, kd=1.0, tau=0.1)
    c.step({"measure": 0.0}, 0.1)
    assert c.step({"measure": 0.5}, 0.1) == pytest.approx(-5.0 * (1.0 - math.exp(-1.0)))


def test_missing_setpoint_means_zero_and_measure_is_required() -> None:
    assert pid(kp=2.0).step({"measure": 0.25}, DT) == -0.5
    with pytest.raises(KeyError, match="no input with role 'measure'"):
        pid().step({"setpoint": 1.0}, DT)


def test_reaches_the_set_point_of_a_first_order_plant() -> None:
    loop = Loop(pid(kp=0.8, ki=2.0))
    loop.run(600, setpoint=1.0)
    assert loop.y == pytest.approx(1.0, abs=1e-3)
    assert loop.outputs[-1] == pytest.approx(0.5, abs=1e-3)


def test_anti_windup_bounds_the_integrator_and_recovers_at_once() -> None:
    loop = Loop(pid(kp=0.5, ki=5.0, outputLimit=1.0))
    loop.run(500, setpoint=10.0)  # unreachable: at most 2 with |u| ≤ 1
    assert max(loop.outputs) == 1.0
    assert loop.controller.state()["integral"] <= 1.0
    loop.run(1, setpoint=0.5)
    assert loop.outputs[-1] < 1.0  # off the limit at the first step, no wound-up integral to unwind
    loop.run(200, setpoint=0.5)
    assert loop.y == pytest.approx(0.5, abs=1e-3)


def test_output_limits() -> None:
    c = pid(kp=10.0, outputMin=-0.2, outputMax=0.3)
    assert c.step({"measure": 0.0, "setpoint": 1.0}, DT) == 0.3
    assert c.step({"measure": 0.0, "setpoint": -1.0}, DT) == -0.2


def test_bumpless_transfer_gives_a_continuous_output() -> None:
    first = Loop(pid(kp=0.8, ki=2.0))
    first.run(30, setpoint=1.0)  # mid-transient
    last = first.outputs[-1]
    second = Loop(pid(kp=0.3, ki=1.0, kd=0.02, tau=0.02), y=first.y)
    second.controller.bumpless(last)
    second.run(50, setpoint=1.0)
    assert second.outputs[0] == pytest.approx(last, abs=1e-12)
    jumps = [abs(b - a) for a, b in zip([last, *second.outputs], second.outputs, strict=False)]
    assert max(jumps) < 0.05
    cold = Loop(pid(kp=0.3, ki=1.0, kd=0.02, tau=0.02), y=first.y)
    cold.run(1, setpoint=1.0)
    assert abs(cold.outputs[0] - last) > 0.2  # without bumpless the output would jump


def test_state_round_trip_continues_identically() -> None:
    original = Loop(pid(kp=0.8, ki=2.0, kd=0.02, tau=0.05, outputLimit=0.9))
    original.run(40, setpoint=1.0)
    state = msgpack.unpackb(msgpack.packb(original.controller.state()))
    copy = Loop(pid(kp=0.8, ki=2.0, kd=0.02, tau=0.05, outputLimit=0.9), y=original.y)
    copy.x = original.x
    copy.controller.restore(state)
    original.run(60, setpoint=0.7)
    copy.run(60, setpoint=0.7)
    assert copy.outputs == original.outputs[40:]


def test_restore_refuses_a_foreign_state() -> None:
    with pytest.raises(ValueError, match="not a pid controller state"):
        pid().restore({"kind": "gpc"})
    with pytest.raises(ValueError, match="lacks previous"):
        pid().restore({"kind": "pid", "integral": 0.0})


def test_future_holds_p_plus_i() -> None:
    c = pid(5, kp=2.0, ki=1.0, kd=3.0)
    assert c.future() == []
    c.step({"measure": 0.0, "setpoint": 1.0}, 0.1)
    c.step({"measure": 0.2, "setpoint": 1.0}, 0.1)
    integral = 0.1 + 0.08
    assert c.future() == pytest.approx([2.0 * 0.8 + integral] * 5)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"kq": "1"}, r"controller 'pid' \(pid\) takes no parameter 'kq'"),
        ({"kp": "fast"}, "parameter 'kp' = 'fast' is not a float"),
        ({"kd": "nan"}, "parameter 'kd' = nan must be finite"),
        ({"tau": "-0.1"}, "parameter 'tau' = -0.1 must not be negative"),
        ({"outputMin": "1", "outputMax": "-1"}, "'outputMin' = 1.0 must be less than 'outputMax' = -1.0"),
        ({"outputLimit": "1", "outputMax": "2"}, "either 'outputLimit' or 'outputMin'/'outputMax'"),
        ({"outputLimit": "0"}, "'outputLimit' = 0.0 must be greater than 0"),
    ],
)
def test_param_errors(params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=message):
        pid(**params)
