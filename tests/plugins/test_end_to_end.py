"""The plugins together, found through the installed entry points: sensor → adaptation chain →
controller → actuator on a loopback plant, stepped by an injected clock."""

from __future__ import annotations

import pytest

from ckmconf import model
from ckmconf.model import HWChannel, Param
from plugins.hardware.loopback import ManualClock, PlantScope, plant_scope
from runtime.kernel.adaptation import build_chain
from runtime.kernel.interfaces import Backend, Controller
from runtime.registry import default_registry

PERIOD = 0.01
ENCODER = {"plant": "motor", "order": "1", "gain": "2", "timeConstant": "0.2"}  # the plant of closed_loop.xml


def test_entry_points_are_registered() -> None:
    registry = default_registry()
    assert {"pid", "gpc"} <= set(registry.kinds("controller"))
    assert "loopback" in registry.kinds("hardware")
    assert {"wrap-angle", "outlier-reject"} <= set(registry.kinds("function"))


def build(kind: str, horizon: int, **params: object) -> tuple[ManualClock, Backend, Backend, Controller]:
    registry = default_registry()
    clock = ManualClock()
    motor = HWChannel(name="pwm", direction="out", params=(Param(name="plant", value="motor"),))
    encoder = HWChannel(
        name="encoder",
        direction="in",
        params=tuple(Param(name=k, value=v) for k, v in ENCODER.items()),
    )
    loopback = registry.resolve("hardware", "loopback")
    with plant_scope(PlantScope(clock)):
        out, sensor = loopback(motor), loopback(encoder)
    out.setup()
    sensor.setup()
    record = model.Controller(
        name="c",
        kind=kind,
        period=PERIOD,
        horizon=horizon,
        params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
    )
    return clock, out, sensor, registry.resolve("controller", kind)(record)


def test_pid_closes_the_loop_through_a_sensor_chain() -> None:
    clock, out, sensor, pid = build("pid", 10, kp=0.8, ki=2.0, outputLimit=1.0)
    adaptation = model.Adaptation(steps=(model.Linear(gain=1.0), model.LowPass(cutoff=20.0)))
    chain = build_chain(adaptation, default_registry(), inverse=False)
    for _ in range(800):
        raw = sensor.read()
        assert isinstance(raw, float)
        out.write(pid.step({"measure": chain(raw, clock()), "setpoint": 1.0}, PERIOD))
        clock.advance(PERIOD)
    assert sensor.read() == pytest.approx(1.0, abs=2e-3)


def test_gpc_stored_actions_keep_the_plant_on_target_when_the_measure_is_lost() -> None:
    clock, out, sensor, gpc = build("gpc", 60, gain=2.0, timeConstant=0.2)
    for _ in range(5):  # the set point just changed; the loop is mid-transient when the measure stops
        raw = sensor.read()
        assert isinstance(raw, float)
        out.write(gpc.step({"measure": raw, "setpoint": 0.8}, PERIOD))
        clock.advance(PERIOD)
    for action in gpc.future():  # what the actuation service plays (§3.1.2.2)
        out.write(action)
        clock.advance(PERIOD)
    assert sensor.read() == pytest.approx(0.8, abs=0.01)
