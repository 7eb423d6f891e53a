"""take-off, fly-to and land over the ``flight`` interface, on the flight service flying a point-mass
airframe (tests/plugins/flight/point_mass.py); on the simulator's multirotors in tests/plugins/sim."""

from __future__ import annotations

import math
from typing import Any

import pytest

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorInput, BehaviorOutput, Uses
from plugins.behaviors.flight import FlyTo, Land, TakeOff
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from tests.plugins.behaviors.closed_loop import OutputsService
from tests.plugins.flight.point_mass import Loop, PointMass, flight_control


def behavior(cls: type[Behavior], loop: Loop, signal: dict[str, Any] | None = None, **params: str) -> Behavior:
    inputs = (BehaviorInput(name="spotted", topic="/spotted"),) if signal is not None else ()
    record = BehaviorRecord(name=cls.__name__.upper(), kind="-", timeout=60.0,
                            uses=(Uses(service="Drone.Flight", as_="flight"),),
                            params=tuple(Param(name=k, value=v) for k, v in params.items()),
                            inputs=inputs, outputs=(BehaviorOutput(name="flight_goal", topic="/drone/goal"),))

    def publish(goal: Any) -> None:
        loop.goal = goal

    flight = OutputsService("Drone.Flight", lambda name: loop.out.get(name), loop.service.apply_service_parameters)
    context = BehaviorContext(services={"flight": flight}, now=lambda: loop.now,
                              inputs={"spotted": lambda: signal} if signal is not None else {},
                              outputs={"flight_goal": publish})
    return cls(record, context)


def run(loop: Loop, state: Behavior, seconds: float) -> BehaviorStatus:
    state.start()
    status = state.step()
    while loop.now < seconds and not (status.done or status.failed):
        loop.run(loop.period)
        status = state.step()
    state.stop()
    return status


def test_take_off_fly_over_a_spotted_object_and_land_there() -> None:
    loop = Loop(flight_control(speed=1.5), PointMass(x=1.0, y=1.0), noise=0.02)
    assert run(loop, behavior(TakeOff, loop, altitude="2.5"), 30.0).done
    assert loop.body.z == pytest.approx(2.5, abs=0.25)
    spotted = {"label": "parcel", "frame": "map", "x": 7.0, "y": 4.0, "z": 0.15}
    assert run(loop, behavior(FlyTo, loop, spotted, altitude="1.5"), 60.0).done
    assert math.dist((loop.body.x, loop.body.y, loop.body.z), (7.0, 4.0, 1.5)) < 0.3
    assert run(loop, behavior(FlyTo, loop, goal="3 3 2 1.57"), 90.0).done
    assert loop.body.yaw == pytest.approx(1.57, abs=0.2)
    assert run(loop, behavior(Land, loop), 120.0).done
    assert loop.body.z == 0.0 and math.hypot(loop.body.x - 3.0, loop.body.y - 3.0) < 0.3


def test_a_flight_refused_by_the_service_fails_the_behavior_with_the_services_reason() -> None:
    loop = Loop(flight_control(), PointMass())  # on the ground: a goto is refused
    status = run(loop, behavior(FlyTo, loop, goal="3 0 2"), 5.0)
    assert status.failed and status.detail.startswith("the flight failed: goal ")
    assert status.detail.endswith(": the robot has landed: take off first")


def test_fly_to_waits_for_a_map_position_and_ignores_one_in_another_frame() -> None:
    loop = Loop(flight_control(), PointMass(z=1.0))
    state = behavior(FlyTo, loop, {"frame": "camera", "x": 1.0, "y": 0.0}, altitude="2")
    state.start()
    assert state.step().detail == "waiting for the goal" and loop.goal is None


@pytest.mark.parametrize(
    ("cls", "signal", "params", "message"),
    [
        (FlyTo, None, {"goal": "3 0"}, "is not 'x y z' or 'x y z yaw'"),
        (FlyTo, None, {}, "parameter 'goal' is required"),
        (FlyTo, {"x": 1, "y": 1}, {}, "needs parameter 'altitude'"),
        (FlyTo, {"x": 1, "y": 1}, {"goal": "1 1 1", "altitude": "2"}, "not both"),
        (TakeOff, None, {"altitude": "-1"}, "altitude"),
    ],
)
def test_bad_params_are_refused_when_the_behavior_is_built(cls: type[Behavior], signal: dict[str, Any] | None,
                                                           params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=message):
        behavior(cls, Loop(flight_control(), PointMass()), signal, **params)
