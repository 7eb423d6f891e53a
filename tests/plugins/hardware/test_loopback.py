"""The loopback backend: analytic step responses under an injected clock, dead time, noise, plant
isolation and Param errors."""

from __future__ import annotations

import dataclasses
import gc
import math
import statistics
import threading
import time
from typing import Literal

import pytest

from ckmconf.loader import load
from ckmconf.model import HWChannel, Param
from plugins.hardware.loopback import LoopbackBackend, find_plant
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from runtime.kernel.interfaces import ParamError
from tests.conftest import CONFIGS
from tests.plugins.test_lti import second_order_step


def channel(name: str, direction: Literal["in", "out"] = "in", /, **params: object) -> HWChannel:
    return HWChannel(
        name=name,
        direction=direction,
        params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
    )


def pair(scope: PlantScope, **params: object) -> tuple[LoopbackBackend, LoopbackBackend]:
    """An output channel carrying the plant Params and an input channel reading the plant."""
    out = LoopbackBackend(channel("u", "out", plant="p", **params), scope=scope)
    sensor = LoopbackBackend(channel("y", plant="p"), scope=scope)
    out.setup()
    sensor.setup()
    return out, sensor


def read(backend: LoopbackBackend) -> float:
    value = backend.read()
    assert isinstance(value, float)
    return value


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(100.0)


def test_first_order_step_response(clock: ManualClock) -> None:
    out, sensor = pair(PlantScope(clock), order=1, gain=2.0, timeConstant=0.2)
    assert read(sensor) == 0.0
    out.write(1.0)
    for i in range(1, 101):
        clock.advance(0.01)
        assert read(sensor) == pytest.approx(2.0 * (1.0 - math.exp(-i * 0.01 / 0.2)), abs=1e-12)
    assert read(out) == 1.0  # an output channel reads back its last value


def test_integration_is_exact_for_any_gap(clock: ManualClock) -> None:
    out, sensor = pair(PlantScope(clock), timeConstant=0.5)  # order 1 implied
    out.write(-3.0)
    clock.advance(0.73)
    assert read(sensor) == pytest.approx(-3.0 * (1.0 - math.exp(-0.73 / 0.5)), abs=1e-12)


@pytest.mark.parametrize("damping", [0.25, 1.0, 2.0])
def test_second_order_step_response(clock: ManualClock, damping: float) -> None:
    out, sensor = pair(PlantScope(clock), order=2, gain=0.5, naturalFrequency=6.0, damping=damping)
    out.write(2.0)
    for i in range(1, 121):
        clock.advance(0.01)
        assert read(sensor) == pytest.approx(second_order_step(1.0, 6.0, damping, i * 0.01), abs=1e-9)


def test_plain_loopback_reads_what_was_written(clock: ManualClock) -> None:
    out, sensor = pair(PlantScope(clock))
    out.write((0.7,))
    assert read(sensor) == 0.7


def test_dead_time(clock: ManualClock) -> None:
    out, sensor = pair(PlantScope(clock), order=1, gain=1.0, timeConstant=0.1, delay=0.05)
    out.write(1.0)
    clock.advance(0.04)
    assert read(sensor) == 0.0
    clock.advance(0.06)  # 0.05 s after the input started acting
    assert read(sensor) == pytest.approx(1.0 - math.exp(-0.5), abs=1e-12)
    out.write(0.0)
    clock.advance(0.05)
    assert read(sensor) == pytest.approx((1.0 - math.exp(-1.0)), abs=1e-12)  # the 0 has not arrived yet


def test_noise_is_deterministic_for_a_seed(clock: ManualClock) -> None:
    def samples(seed: int) -> list[float]:
        out, sensor = pair(PlantScope(clock), gain=1.0, noise=0.1, seed=seed)
        out.write(5.0)
        return [read(sensor) for _ in range(2000)]

    first = samples(7)
    assert samples(7) == first
    assert samples(8) != first
    assert statistics.fmean(first) == pytest.approx(5.0, abs=0.01)
    assert statistics.pstdev(first) == pytest.approx(0.1, rel=0.1)


def test_plants_of_different_scopes_are_separate(clock: ManualClock) -> None:
    out_a, sensor_a = pair(PlantScope(clock))
    out_b, sensor_b = pair(PlantScope(clock))  # same plant name "p"
    out_a.write(1.0)
    out_b.write(2.0)
    assert (read(sensor_a), read(sensor_b)) == (1.0, 2.0)


def test_plant_scope_block_is_shared_by_the_backends_built_in_it(clock: ManualClock) -> None:
    with plant_scope(PlantScope(clock)) as scope:
        out = LoopbackBackend(channel("u", "out", plant="p"))
        sensor = LoopbackBackend(channel("y", plant="p"))
    with plant_scope():
        stranger = LoopbackBackend(channel("y", plant="p"))
    assert out.scope is scope and sensor.scope is scope and stranger.scope is not scope
    for backend in (out, sensor, stranger):
        backend.setup()
    out.write(4.0)
    assert (read(sensor), read(stranger)) == (4.0, 0.0)


def test_plant_goes_away_with_its_last_backend(clock: ManualClock) -> None:
    scope = PlantScope(clock)
    out, sensor = pair(scope)
    plant = find_plant("p", scope)
    assert plant is not None and out.plant is plant
    plant.set_input(3.0)  # what an operator console or a test does for an input-only plant
    assert read(sensor) == 3.0
    out.stop()
    sensor.stop()
    del out, sensor, plant
    gc.collect()
    assert find_plant("p", scope) is None


def test_example_params_on_either_channel_merge(clock: ManualClock) -> None:
    node = load(CONFIGS / "examples" / "closed_loop.xml").nodes[0]
    with plant_scope(PlantScope(clock)):
        encoder, pwm = (LoopbackBackend(c) for c in node.channels)
    encoder.setup()
    pwm.setup()
    pwm.write(0.5)
    clock.advance(0.2)
    gain = 2000.0  # the example's pwm channel: ticks/s per unit of duty
    assert read(encoder) == pytest.approx(gain * 0.5 * (1.0 - math.exp(-1.0)), abs=1e-9)


def test_conflicting_params_name_both_channels(clock: ManualClock) -> None:
    scope = PlantScope(clock)
    first = LoopbackBackend(channel("u", "out", plant="p", gain=2), scope=scope)
    first.setup()  # kept: a plant lives while a backend holds it
    late = LoopbackBackend(channel("y", plant="p", gain=3), scope=scope)
    with pytest.raises(ParamError, match=r"parameter 'gain' = 3.0 on channel 'y' conflicts with 2.0 on channel 'u'"):
        late.setup()
    with pytest.raises(ParamError, match="channel 'z': parameter 'timeConstant' does not apply to a plant of order 2"):
        LoopbackBackend(channel("z", plant="p", damping=0.5, timeConstant=1), scope=scope)  # damping implies order 2


def test_params_together_must_describe_one_plant(clock: ManualClock) -> None:
    scope = PlantScope(clock)
    first = LoopbackBackend(channel("u", "out", plant="p", order=1), scope=scope)
    first.setup()
    with pytest.raises(ParamError, match=r"\(Params of its channels together\): parameter 'damping' does not apply"):
        LoopbackBackend(channel("y", plant="p", damping=0.5), scope=scope).setup()


def test_params_cannot_arrive_after_the_plant_started(clock: ManualClock) -> None:
    out, sensor = pair(PlantScope(clock))
    read(sensor)
    late = LoopbackBackend(channel("v", plant="p", gain=2), scope=out.scope)
    with pytest.raises(ParamError, match="'gain' on channel 'v' comes after the plant started"):
        late.setup()


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"bogus": 1}, r"channel 'y' takes no parameter 'bogus' \(accepted: damping, delay, gain, naturalFrequency, "),
        ({"order": "two"}, "loopback channel 'y': parameter 'order' = 'two' is not a int"),
        ({"order": 3}, "parameter 'order' = 3 must be one of 0, 1, 2"),
        ({"timeConstant": -1}, "'timeConstant' = -1.0 must be greater than 0"),
        ({"order": 1, "naturalFrequency": 2}, "'naturalFrequency' does not apply to a plant of order 1"),
        ({"noise": -0.1}, "'noise' = -0.1 must not be negative"),
        ({"delay": "later"}, "'delay' = 'later' is not a float"),
    ],
)
def test_param_errors(params: dict[str, object], message: str) -> None:
    with pytest.raises(ParamError, match=message):
        LoopbackBackend(channel("y", **params), scope=PlantScope())


def test_size_must_be_one() -> None:
    with pytest.raises(ParamError, match="size is 3, a loopback plant has one output"):
        LoopbackBackend(dataclasses.replace(channel("y"), size=3), scope=PlantScope())


def test_misuse_is_reported(clock: ManualClock) -> None:
    sensor = LoopbackBackend(channel("y"), scope=PlantScope(clock))
    with pytest.raises(RuntimeError, match="before setup"):
        sensor.read()
    sensor.setup()
    with pytest.raises(RuntimeError, match="is an input channel"):
        sensor.write(1.0)


def test_concurrent_use_is_safe() -> None:
    clock = ManualClock()
    out, sensor = pair(PlantScope(clock), order=2, naturalFrequency=3.0)
    errors: list[BaseException] = []

    def hammer(worker: int) -> None:
        try:
            for i in range(500):
                out.write(float(worker + i % 3))
                read(sensor)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=hammer, args=(w,)) for w in range(4)]
    for thread in threads:
        thread.start()
    for _ in range(200):
        clock.advance(0.001)
    for thread in threads:
        thread.join()
    assert errors == []
    assert math.isfinite(read(sensor))


def test_real_time_by_default() -> None:
    out, sensor = pair(PlantScope(), order=1, gain=1.0, timeConstant=1e-4)
    out.write(1.0)
    time.sleep(0.002)
    assert 0.9 < read(sensor) <= 1.0
