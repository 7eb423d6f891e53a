"""``controller.back-off``: a base that hit something backs away from it, then stands (§7.1, D231).

A Kobuki's safety controller answers a bumper hit by reversing a little, so that the base no longer
presses on the obstacle and the navigation above it can plan round it. A plain controlled stop
(``ramp-stop``) leaves the bumper pressed, and a base whose kinematics only come back once the
bumper is released then stays against the obstacle for good. back-off starts from the outputs of
the controller it takes over from (bumpless) or from its ``measure`` inputs (one per output), drives
every output toward ``-speed`` for ``duration`` seconds after it became active, then toward 0. Each
output moves by at most ``acceleration`` per second, so the reverse starts and ends without a jolt.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import read_params
from runtime.verification.manifest import NUMBER, P, Params, Ports

from .common import check_state, toward
from .multi import MultiOutputController, Row, measured_row, measured_size


class BackOff(MultiOutputController):
    """Reverse every output at ``speed`` for ``duration`` seconds, then stop (the bumper's answer)."""

    kind = "back-off"
    PARAMS = Params(
        P(
            "speed",
            0.1,
            "Reverse speed of every output (the wheels' rim speed when they are m/s).",
            type=float,
            unit="output unit",
            above=0.0,
        ),
        P(
            "duration",
            1.0,
            "Seconds of reverse after the controller became active; then 0.",
            type=float,
            unit="s",
            above=0.0,
        ),
        P(
            "acceleration",
            1.0,
            "Largest change of an output per second.",
            type=float,
            unit="1/s · output unit",
            above=0.0,
        ),
    )
    PORTS = Ports(inputs={"measure": NUMBER, "*": NUMBER}, outputs={"*": NUMBER})

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.size = measured_size(record, self.owner)
        params = read_params(record.params, self.PARAMS, owner=self.owner)
        self.speed: float = params["speed"]
        self.duration: float = params["duration"]
        self.acceleration: float = params["acceleration"]
        self._outputs: Row | None = None  # None: take the measures at the next step
        self._active = 0.0  # seconds since the controller took over
        self._last: float | None = None  # when it last stepped: a gap means it was off and took over again

    def _target(self, active: float) -> float:
        return -self.speed if active < self.duration else 0.0

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Every output one period further toward the reverse speed (or 0 once it has reversed long enough)."""
        dt = dt if dt > 0.0 else self.record.period
        now = time.monotonic()
        if self._last is not None and now - self._last > 2.5 * self.record.period:  # active again, no output given
            self._outputs, self._active = None, 0.0
        self._last = now
        if self._outputs is None:
            self._outputs = measured_row(inputs, self.size)
        target = self._target(self._active)
        self._outputs = tuple(toward(v, target, self.acceleration * dt) for v in self._outputs)
        self._active += dt
        return self._outputs

    def future_outputs(self) -> list[Row]:
        """The same ramp over the horizon (empty before the first step)."""
        rows, outputs, active = [], self._outputs, self._active
        if outputs is None:
            return []
        for _ in range(self.record.horizon):
            target = self._target(active)
            outputs = tuple(toward(v, target, self.acceleration * self.record.period) for v in outputs)
            active += self.record.period
            rows.append(outputs)
        return rows

    def bumpless(self, output: Any) -> None:
        """Take over: the reverse starts now, from ``output`` (or from the measures when it is not a row)."""
        self._outputs = self.as_row(output, self.size)
        self._active, self._last = 0.0, None

    def state(self) -> dict[str, Any]:
        """Outputs and time active (code delegation, §3.1.2.6)."""
        return {
            "kind": self.kind,
            "outputs": None if self._outputs is None else list(self._outputs),
            "active": self._active,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a back-off controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("outputs", "active"))
        outputs = state["outputs"]
        self._outputs = None if outputs is None else tuple(float(v) for v in outputs)
        self._active, self._last = float(state["active"]), None
