"""``controller.diff-drive`` and ``controller.ramp-stop``: the Kobuki base's kinematics and its safe stop (§7.1).

diff-drive turns a velocity command (``Twist``: ``linear`` m/s, ``angular`` rad/s, role
``setpoint``) into the two wheel speed set points of a differential base (outputs: left, then
right), by the inverse kinematics

    v_left = v − ω·b/2,   v_right = v + ω·b/2      (b = ``wheelBase``)

after bounding v to ±``maxLinear`` and ω to ±``maxAngular``. A wheel above ``maxWheelSpeed``
scales both wheels down by the same factor, so the path's curvature is kept. Each set point moves
by at most ``maxAcceleration``·dt per period. ``output="angular"`` gives wheel speeds in rad/s
(divided by ``wheelRadius``) instead of rim speeds in m/s. A missing command means "stand still".

ramp-stop brings every output to rest with a bounded deceleration: it starts from the outputs of
the controller it takes over from (bumpless) or, without them, from its ``measure`` inputs (one
per output), and moves all of them toward 0 together, the fastest at ``deceleration`` per second,
the others proportionally, so the base stops on its current arc rather than swerving (D91).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import ParamError, read_params
from runtime.verification.manifest import MAPPING, NUMBER, REQUIRED, P, Params, Ports

from .common import check_state, clamp, toward
from .multi import MultiOutputController, Row, field, measured_row, measured_size


class DiffDrive(MultiOutputController):
    """Inverse kinematics of a differential-drive base: Twist → left and right wheel set points."""

    kind = "diff-drive"
    PARAMS = Params(
        P("wheelBase", REQUIRED, "Distance between the wheels' contact points.", type=float, unit="m", above=0.0),
        P("wheelRadius", 0.0, "Wheel radius (needed for output=angular only).", unit="m", min=0.0),
        P("maxLinear", math.inf, "Largest linear speed commanded; faster commands are bounded.", unit="m/s", above=0.0),
        P("maxAngular", math.inf, "Largest turn rate commanded.", unit="rad/s", above=0.0),
        P("maxWheelSpeed", math.inf, "Largest wheel rim speed; both wheels scale down to keep the curvature.",
          unit="m/s", above=0.0),
        P("maxAcceleration", math.inf, "Largest change of a wheel set point per second.", unit="m/s^2", above=0.0),
        P("output", "linear", "Wheel set points as rim speeds (linear, m/s) or wheel rates (angular, rad/s).",
          choices=("linear", "angular")),
    )
    PORTS = Ports(inputs={"setpoint": MAPPING, "*": NUMBER}, outputs={"*": NUMBER})  # a Twist-like message

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record, outputs=2)
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        self.base: float = values["wheelBase"]
        self.max_linear: float = values["maxLinear"]
        self.max_angular: float = values["maxAngular"]
        self.max_wheel: float = values["maxWheelSpeed"]
        self.max_accel: float = values["maxAcceleration"]
        self.scale = 1.0
        if values["output"] == "angular":
            if not values["wheelRadius"] > 0.0:
                raise ParamError(f"{self.owner}: output 'angular' needs parameter 'wheelRadius' greater than 0")
            self.scale = 1.0 / values["wheelRadius"]
        self._wheels: Row = (0.0, 0.0)
        self._target: Row = (0.0, 0.0)

    def wheel_speeds(self, linear: float, angular: float) -> tuple[float, float]:
        """The bounded (left, right) wheel speeds for a Twist, before the acceleration limit."""
        v = clamp(linear, -self.max_linear, self.max_linear)
        w = clamp(angular, -self.max_angular, self.max_angular)
        left, right = v - w * self.base / 2.0, v + w * self.base / 2.0
        top = max(abs(left), abs(right))
        if top > self.max_wheel:
            left, right = left * self.max_wheel / top, right * self.max_wheel / top
        return left * self.scale, right * self.scale

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Left and right wheel speeds, ramped toward the Twist set point within ``maxAcceleration``.

        A missing set point stops the base; the set point is a Twist message or a ``(linear, angular)`` pair.
        """
        command = inputs.get("setpoint")
        if command is None:
            self._target = (0.0, 0.0)
        elif isinstance(command, Mapping):
            what = "velocity command"
            linear = field(command, "linear", owner=self.owner, what=what)
            self._target = self.wheel_speeds(linear, field(command, "angular", owner=self.owner, what=what))
        else:
            linear, angular = (float(v) for v in command)
            self._target = self.wheel_speeds(linear, angular)
        step = self.max_accel * self.scale * (dt if dt > 0.0 else self.record.period)
        self._wheels = tuple(toward(w, t, step) for w, t in zip(self._wheels, self._target, strict=True))
        return self._wheels

    def future_outputs(self) -> list[Row]:
        """The ramp toward the current command, then the command held."""
        rows, wheels = [], self._wheels
        step = self.max_accel * self.scale * self.record.period
        for _ in range(self.record.horizon):
            wheels = tuple(toward(w, t, step) for w, t in zip(wheels, self._target, strict=True))
            rows.append(wheels)
        return rows

    def bumpless(self, output: Any) -> None:
        """Start the ramp from the wheel speeds ``output`` (when it is a pair)."""
        row = self.as_row(output, 2)
        if row is not None:
            self._wheels = row

    def state(self) -> dict[str, Any]:
        """Wheel speeds and target (code delegation, §3.1.2.6)."""
        return {"kind": self.kind, "wheels": list(self._wheels), "target": list(self._target)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a diff-drive controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("wheels", "target"))
        self._wheels = tuple(float(v) for v in state["wheels"])
        self._target = tuple(float(v) for v in state["target"])


class RampStop(MultiOutputController):
    """Brings every output to 0 with bounded deceleration (the safe/hold controller of a base)."""

    kind = "ramp-stop"
    PARAMS = Params(
        P("deceleration", REQUIRED, "Largest decrease of an output's magnitude per second.", type=float,
          unit="1/s · output unit", above=0.0),
    )
    PORTS = Ports(inputs={"measure": NUMBER, "*": NUMBER}, outputs={"*": NUMBER})

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.size = measured_size(record, self.owner)
        self.deceleration: float = read_params(record.params, self.PARAMS, owner=self.owner)["deceleration"]
        self._outputs: Row | None = None  # None: take the measures at the next step

    def _ramp(self, outputs: Row, dt: float) -> Row:
        top = max((abs(v) for v in outputs), default=0.0)
        if top <= self.deceleration * dt:
            return (0.0,) * len(outputs)
        factor = (top - self.deceleration * dt) / top
        return tuple(v * factor for v in outputs)

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Every output one period further toward 0 (starting from the measured speeds)."""
        if self._outputs is None:
            self._outputs = measured_row(inputs, self.size)
        self._outputs = self._ramp(self._outputs, dt if dt > 0.0 else self.record.period)
        return self._outputs

    def future_outputs(self) -> list[Row]:
        """The ramp to 0 over the horizon (empty before the first step)."""
        rows, outputs = [], self._outputs
        if outputs is None:
            return []
        for _ in range(self.record.horizon):
            outputs = self._ramp(outputs, self.record.period)
            rows.append(outputs)
        return rows

    def bumpless(self, output: Any) -> None:
        """Start from ``output``, or from the measured speeds at the next step when it is not a row."""
        self._outputs = self.as_row(output, self.size)  # None: start from the measured speeds

    def state(self) -> dict[str, Any]:
        """The outputs (code delegation, §3.1.2.6)."""
        return {"kind": self.kind, "outputs": None if self._outputs is None else list(self._outputs)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a ramp-stop controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("outputs",))
        outputs = state["outputs"]
        self._outputs = None if outputs is None else tuple(float(v) for v in outputs)
