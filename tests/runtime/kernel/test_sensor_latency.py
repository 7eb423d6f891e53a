"""A backend with a latency (a simulated camera, D246) is read in two phases: the sensor asks at its
instant and publishes the value ``latency`` later, stamped at the ask; a failed collect fails the
sensor's next period, where the scheduler counts it."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from ckmconf.model import HWChannel, Sensor
from runtime.kernel.interfaces import Backend, Value
from runtime.kernel.services import SensorService
from runtime.network.api import Publisher, TopicQoS
from tests import waiting


class SlowCamera(Backend):
    """Hands out numbered reads; ``broken`` makes the next collect fail."""

    latency = 0.05

    def __init__(self) -> None:
        super().__init__(HWChannel(name="camera", direction="in", kind="analog"))
        self.asked: list[tuple[int, float]] = []
        self.collected: list[tuple[int, float]] = []
        self.broken = False
        self.lock = threading.Lock()

    def read(self) -> Value:
        raise AssertionError("a backend with a latency is read in two phases")

    def write(self, value: Value) -> None:
        raise AssertionError("an input channel")

    def request(self) -> Any:
        with self.lock:
            self.asked.append((len(self.asked) + 1, time.monotonic()))
            return len(self.asked)

    def collect(self, token: Any) -> Value:
        self.collected.append((token, time.monotonic()))
        if self.broken:
            raise ConnectionError("the world server is gone")
        return float(token)


@pytest.fixture
def sensor() -> tuple[SensorService, SlowCamera, list[tuple[Any, float]]]:
    published: list[tuple[Any, float]] = []

    def send(qos: TopicQoS, value: Any, stamp: float) -> int:
        published.append((value, stamp))
        return 0

    backend = SlowCamera()
    record = Sensor(name="camera", channel="camera", topic="frames", period=0.1)
    return SensorService(record, backend, lambda x, now: x, Publisher(TopicQoS("frames"), send)), backend, published


def test_the_value_comes_latency_later_stamped_at_the_ask(
    sensor: tuple[SensorService, SlowCamera, list[tuple[Any, float]]],
) -> None:
    service, backend, published = sensor
    stamps = []
    for _ in range(3):
        stamps.append(time.time())
        service.tick()
    assert waiting.until(lambda: len(published) == 3)
    assert [value for value, _ in published] == [1.0, 2.0, 3.0]
    assert [stamp for _, stamp in published] == pytest.approx(stamps, abs=0.01)  # the ask's instant, not the collect's
    for (_, asked), (_, collected) in zip(backend.asked, backend.collected, strict=True):
        assert collected >= asked + backend.latency  # collected no sooner than the latency says
    service.stop()


def test_a_failed_collect_fails_the_next_period(sensor: tuple[SensorService, SlowCamera, list[Any]]) -> None:
    service, backend, published = sensor
    backend.broken = True
    service.tick()
    assert waiting.until(lambda: service.failure is not None)
    with pytest.raises(ConnectionError, match="the world server is gone"):
        service.tick()
    backend.broken = False
    service.tick()  # the failure was raised once (that period asked nothing); the sensor goes on
    assert waiting.until(lambda: len(published) == 1)
    assert published[0][0] == 2.0 and len(backend.asked) == 2
    service.stop()


def test_reads_in_flight_when_the_sensor_stops_are_dropped(
    sensor: tuple[SensorService, SlowCamera, list[Any]],
) -> None:
    service, backend, published = sensor
    backend.latency = 0.3
    service.tick()
    service.tick()
    service.stop()  # the channel closes next: nothing may be collected from it
    assert service._orders is not None
    assert waiting.until(lambda: service._orders is not None and service._orders.empty())
    time.sleep(0.4)  # past the reads' latency
    assert backend.collected == [] and published == [] and service.failure is None
