"""The GPC: set-point tracking on its model plant, stored future actions played open-loop, offset-free
control despite model errors, bumpless transfer, state round-trip and Param errors."""

from __future__ import annotations

import math

import msgpack
import pytest

from ckmconf.loader import load
from plugins.controllers.gpc import GPC
from plugins.lti import PlantModel, Vector
from runtime.kernel.interfaces import ParamError
from tests.conftest import CONFIGS
from tests.plugins.controllers.records import controller_record

DT = 0.01
PLANT = PlantModel(order=1, gain=2.0, time_constant=0.2)
MODEL: dict[str, object] = {"gain": 2.0, "timeConstant": 0.2}


def gpc(horizon: int = 30, /, **params: object) -> GPC:
    return GPC(controller_record("gpc", DT, horizon, **params))


Run = tuple[Vector, list[float], list[float]]


def run(controller: GPC, plant: PlantModel, steps: int, setpoint: float, x: Vector | None = None) -> Run:
    """Close the loop for ``steps`` periods; returns the final state, the outputs and the actions."""
    x = plant.equilibrium(0.0) if x is None else x
    ys, us = [], []
    for _ in range(steps):
        u = controller.step({"measure": x[0], "setpoint": setpoint}, DT)
        x = plant.advance(x, u, DT)
        ys.append(x[0])
        us.append(u)
    return x, ys, us


def test_one_step_deadbeat_by_hand() -> None:
    c = gpc(predictionHorizon=1, controlHorizon=1, **{"lambda": 0.0}, **MODEL)
    b = 2.0 * (1.0 - math.exp(-DT / 0.2))  # y[k+1] = a·y[k] + b·u[k]
    assert c.step({"measure": 0.0, "setpoint": 1.0}, DT) == pytest.approx(1.0 / b)
    assert PLANT.advance((0.0,), 1.0 / b, DT)[0] == pytest.approx(1.0)


def test_reaches_the_set_point_of_its_model_plant() -> None:
    _, ys, _ = run(gpc(**MODEL), PLANT, 100, setpoint=1.0)
    assert ys[-1] == pytest.approx(1.0, abs=1e-6)
    assert max(ys) < 1.1


def test_future_played_open_loop_keeps_the_plant_near_the_set_point() -> None:
    c = gpc(40, **MODEL)
    x, _, _ = run(c, PLANT, 3, setpoint=1.0)  # mid-transient: y is still far from 1
    assert x[0] < 0.8
    future = c.future()
    assert len(future) == 40
    for u in future:  # the inputs are lost: the actuation service plays the stored actions
        x = PLANT.advance(x, u, DT)
    assert x[0] == pytest.approx(1.0, abs=0.01)
    assert future[-1] == pytest.approx(0.5, abs=0.01)  # ending on the steady-state action


def test_prediction_and_stored_horizons_are_separate() -> None:
    controllers = load(CONFIGS / "examples" / "controller_switching.xml").nodes[0].controllers
    record = next(c for c in controllers if c.kind == "gpc")
    c = GPC(record)  # horizon 50, predictionHorizon 20
    assert c.n == 20
    c.step({"measure": 0.0, "setpoint": 1.0, "feedforward": 3.0}, record.period)
    assert len(c.future()) == 50


def test_offset_free_despite_model_error_and_disturbance() -> None:
    wrong = PlantModel(order=1, gain=2.6, time_constant=0.3)
    _, ys, _ = run(gpc(**MODEL), wrong, 300, setpoint=1.0)
    assert ys[-1] == pytest.approx(1.0, abs=1e-4)


def test_second_order_model() -> None:
    plant = PlantModel(order=2, gain=1.0, natural_frequency=8.0, damping=0.3)
    c = gpc(50, order=2, gain=1.0, naturalFrequency=8.0, damping=0.3)
    _, ys, _ = run(c, plant, 200, setpoint=1.0)
    assert ys[-1] == pytest.approx(1.0, abs=1e-4)
    assert max(ys) < 1.15  # the open-loop plant would overshoot by 37 %


def test_output_limits_hold_and_do_not_wind_up() -> None:
    _, ys, us = run(gpc(outputLimit=1.0, **MODEL), PLANT, 150, setpoint=1.5)
    assert max(us) == 1.0
    assert ys[-1] == pytest.approx(1.5, abs=1e-3)
    assert max(ys) < 1.55


def test_bumpless_transfer_continues_from_the_previous_output() -> None:
    x = PLANT.equilibrium(0.5)  # another controller held the plant at y = 1 with u = 0.5
    taking_over = gpc(**MODEL)
    taking_over.bumpless(0.5)
    _, _, us = run(taking_over, PLANT, 20, setpoint=1.0, x=x)
    assert us == pytest.approx([0.5] * 20, abs=1e-9)
    _, _, cold = run(gpc(**MODEL), PLANT, 1, setpoint=1.0, x=x)
    assert cold[0] == pytest.approx(0.0, abs=1e-9)  # without it the action would drop to 0


def test_state_round_trip_continues_identically() -> None:
    original = gpc(order=2, gain=1.0, naturalFrequency=8.0, damping=0.3, outputLimit=3)
    plant = PlantModel(order=2, gain=1.0, natural_frequency=8.0, damping=0.3)
    x, _, _ = run(original, plant, 25, setpoint=1.0)
    copy = gpc(order=2, gain=1.0, naturalFrequency=8.0, damping=0.3, outputLimit=3)
    copy.restore(msgpack.unpackb(msgpack.packb(original.state())))
    assert copy.future() == original.future()
    _, ys1, us1 = run(original, plant, 40, setpoint=0.5, x=x)
    _, ys2, us2 = run(copy, plant, 40, setpoint=0.5, x=x)
    assert (us1, ys1) == (us2, ys2)


def test_restore_refuses_a_state_of_another_model() -> None:
    first_order = gpc(**MODEL)
    first_order.step({"measure": 0.0}, DT)
    with pytest.raises(ValueError, match="model of another order"):
        gpc(order=2).restore(first_order.state())
    with pytest.raises(ValueError, match="not a gpc controller state"):
        gpc().restore({"kind": "pid"})


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"horizon2": "3"}, r"controller 'gpc' \(gpc\) takes no parameter 'horizon2'"),
        ({"order": "3"}, "parameter 'order' = 3 must be one of 1, 2"),
        ({"damping": "0.5"}, "'damping' does not apply to a plant of order 1"),
        ({"controlHorizon": "40"}, "'controlHorizon' = 40 must be from 1 to 30"),
        ({"predictionHorizon": "0"}, "'predictionHorizon' = 0 must be at least 1"),
        ({"lambda": "-1"}, "'lambda' = -1.0 must not be negative"),
        ({"timeConstant": "soon"}, "'timeConstant' = 'soon' is not a float"),
    ],
)
def test_param_errors(params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=message):
        gpc(**params)
