"""back-off (D231): after a bumper hit the wheels reverse at ``speed`` for ``duration`` seconds with a
bounded acceleration, then stop; a second take-over reverses again; bad Params are named."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from plugins.controllers import backoff
from plugins.controllers.backoff import BackOff
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.vector_records import record

DT = 0.02
WHEELS = [("left_speed", "measure"), ("right_speed", "measure")]
SETPOINTS = ["left_setpoint", "right_setpoint"]


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> _Clock:
    fake = _Clock()
    monkeypatch.setattr(backoff, "time", SimpleNamespace(monotonic=fake))
    return fake


def back_off(horizon: int = 10, **params: object) -> BackOff:
    values: dict[str, object] = {"speed": 0.1, "duration": 1.0, "acceleration": 1.0, **params}
    return BackOff(record("back-off", DT, WHEELS, SETPOINTS, horizon, **values))


def _run(c: BackOff, clock: _Clock, steps: int, measures: tuple[float, float] = (0.0, 0.0)) -> list[tuple[float, ...]]:
    rows = []
    for _ in range(steps):
        clock.now += DT
        rows.append(c.step_outputs({"measure[0]": measures[0], "measure[1]": measures[1]}, DT))
    return rows


def test_reverses_for_its_duration_with_bounded_acceleration_then_stops(clock: _Clock) -> None:
    c = back_off()
    c.bumpless((0.3, 0.2))  # taking over from the kinematics, the base still driving forward
    rows = _run(c, clock, 80)
    previous: tuple[float, ...] = (0.3, 0.2)
    for row in rows:
        assert all(abs(a - b) <= 1.0 * DT + 1e-12 for a, b in zip(row, previous, strict=True))
        previous = row
    assert rows[9] == pytest.approx((0.1, 0.0))  # still slowing after 0.2 s
    assert rows[45] == pytest.approx((-0.1, -0.1))  # reversing at its speed
    assert rows[-1] == (0.0, 0.0)  # then still
    travelled = sum(row[0] for row in rows) * DT
    assert -0.1 < travelled < 0.0  # net backwards (it first had to stop its forward speed)


def test_starts_from_the_measures_and_a_new_take_over_reverses_again(clock: _Clock) -> None:
    c = back_off(horizon=5)
    first = _run(c, clock, 1, measures=(0.05, 0.05))[0]
    assert first == pytest.approx((0.03, 0.03))
    assert len(c.future_outputs()) == 5 and c.future_outputs()[-1] == pytest.approx((-0.07, -0.07))
    assert _run(c, clock, 100)[-1] == (0.0, 0.0)
    clock.now += 5.0  # off for a while, then active again without an output to start from
    again = _run(c, clock, 30)
    assert again[-1] == pytest.approx((-0.1, -0.1))
    other = back_off()
    other.restore(c.state())
    assert other.step_outputs({}, DT) == c.step_outputs({}, DT)


def test_bad_params_and_ports_are_named() -> None:
    with pytest.raises(ParamError, match="speed"):
        back_off(speed=0)
    with pytest.raises(ParamError, match="duration"):
        back_off(duration=-1)
    with pytest.raises(ParamError, match="one 'measure' input per output"):
        BackOff(record("back-off", DT, [("a", "measure")], SETPOINTS))
