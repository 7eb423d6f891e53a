"""``controller.twist-axes``: a velocity command split into one set point per axis (§3.1.2.2).

A holonomic body — a multirotor flown by velocity set-points (PX4 offboard, MAVROS
``setpoint_velocity``), an omnidirectional base — takes one scalar set point per axis, each on an
actuator of its own (an Actuator is scalar, with its own bounds, rate limit and safe value). This
controller reads a velocity command (role ``setpoint``: a ``geometry_msgs/Twist`` ``{linear: {x, y,
z}, angular: {x, y, z}}``, or CKM's planar ``{linear, angular}``) and writes, on its Outputs in
document order, the fields that Param ``axes`` names in that order (``linear.x linear.y linear.z
angular.z`` for a multirotor). Each is bounded by ``maxLinear`` (the three linear axes together, as
a vector, so the direction is kept) or ``maxAngular``, and moves by at most ``maxAcceleration``
(linear) or ``maxAngularAcceleration`` per second. A missing command means "hold": every axis
ramps to 0 (zero velocity: a multirotor hovers where it is).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import ParamError, read_params
from runtime.verification.manifest import MAPPING, NUMBER, REQUIRED, P, Params, Ports

from .common import check_state, toward
from .multi import MultiOutputController, Row

AXES = ("linear.x", "linear.y", "linear.z", "angular.x", "angular.y", "angular.z")
PLANAR = {"linear.x": "linear", "angular.z": "angular"}  # CKM's planar Twist {linear, angular}


def _axis_value(command: Mapping[str, Any], axis: str, owner: str) -> float:
    """The value of ``axis`` in a Twist (nested) or a planar Twist; 0 for a planar one's absent axes."""
    group, name = axis.split(".")
    part = command.get(group)
    if isinstance(part, Mapping):
        value = part.get(name, 0.0)
    elif isinstance(part, int | float) and not isinstance(part, bool) and PLANAR.get(axis) == group:
        value = part
    elif part is None or isinstance(part, int | float):
        value = 0.0  # a planar Twist has no y, z, roll or pitch
    else:
        raise TypeError(f"{owner}: the velocity command's {group!r} must be a vector or a number, got {part!r}")
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}: the velocity command's {axis} = {value!r} is not a finite number")
    return float(value)


class TwistAxes(MultiOutputController):
    """A velocity command (Twist) → one set point per axis named by ``axes`` (see the module docstring)."""

    kind = "twist-axes"
    PARAMS = Params(
        P("axes", REQUIRED, "The Twist fields the Outputs carry, in their order (e.g. 'linear.x linear.y "
          "linear.z angular.z').", type=str),
        P("maxLinear", math.inf, "Largest linear speed (the linear axes together); faster commands are scaled "
          "down along their direction.", unit="m/s", above=0.0),
        P("maxAngular", math.inf, "Largest rate about each angular axis.", unit="rad/s", above=0.0),
        P("maxAcceleration", math.inf, "Largest change of a linear set point per second.", unit="m/s^2", above=0.0),
        P("maxAngularAcceleration", math.inf, "Largest change of an angular set point per second.",
          unit="rad/s^2", above=0.0),
    )
    PORTS = Ports(inputs={"setpoint": MAPPING, "*": NUMBER}, outputs={"*": NUMBER})

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        self.axes: tuple[str, ...] = tuple(str(values["axes"]).split())
        unknown = [a for a in self.axes if a not in AXES]
        if not self.axes or unknown or len(set(self.axes)) != len(self.axes):
            raise ParamError(f"{self.owner}: parameter 'axes' = {values['axes']!r} must name distinct Twist fields "
                             f"among {', '.join(AXES)}" + (f" (not {', '.join(unknown)})" if unknown else ""))
        if len(record.outputs) != len(self.axes):
            raise ParamError(f"{self.owner}: parameter 'axes' names {len(self.axes)} axes but the controller has "
                             f"{len(record.outputs)} Outputs (one per axis, in the same order)")
        self.max_linear: float = values["maxLinear"]
        self.max_angular: float = values["maxAngular"]
        self.max_accel: float = values["maxAcceleration"]
        self.max_angular_accel: float = values["maxAngularAcceleration"]
        self._values: Row = tuple(0.0 for _ in self.axes)
        self._target: Row = self._values

    def bounded(self, command: Mapping[str, Any]) -> Row:
        """The command's axes, the linear ones scaled to ``maxLinear`` together, the angular ones clamped."""
        raw = {axis: _axis_value(command, axis, self.owner) for axis in AXES}
        speed = math.sqrt(sum(raw[a] ** 2 for a in AXES[:3]))
        scale = self.max_linear / speed if speed > self.max_linear else 1.0
        limited = {a: raw[a] * scale for a in AXES[:3]}
        limited |= {a: max(-self.max_angular, min(self.max_angular, raw[a])) for a in AXES[3:]}
        return tuple(limited[a] for a in self.axes)

    def _ramp(self, values: Row, dt: float) -> Row:
        steps = [(self.max_accel if a.startswith("linear") else self.max_angular_accel) * dt for a in self.axes]
        return tuple(toward(v, t, s) for v, t, s in zip(values, self._target, steps, strict=True))

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Each axis ramped toward the command's (0 without one)."""
        command = inputs.get("setpoint")
        if command is None:
            self._target = tuple(0.0 for _ in self.axes)
        elif isinstance(command, Mapping):
            self._target = self.bounded(command)
        else:
            raise TypeError(f"{self.owner}: the velocity command must be a Twist message, got {command!r}")
        self._values = self._ramp(self._values, dt if dt > 0.0 else self.record.period)
        return self._values

    def future_outputs(self) -> list[Row]:
        """The ramp toward the current command, then the command held."""
        rows, values = [], self._values
        for _ in range(self.record.horizon):
            values = self._ramp(values, self.record.period)
            rows.append(values)
        return rows

    def bumpless(self, output: Any) -> None:
        """Start from the set points ``output`` (one per axis)."""
        row = self.as_row(output, len(self.axes))
        if row is not None:
            self._values = row

    def state(self) -> dict[str, Any]:
        """Set points and target (code delegation, §3.1.2.6)."""
        return {"kind": self.kind, "values": list(self._values), "target": list(self._target)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a twist-axes controller.

        Raises:
            ValueError: the state is not one, or has another number of axes.
        """
        check_state(state, self.kind, ("values", "target"))
        values, target = tuple(float(v) for v in state["values"]), tuple(float(v) for v in state["target"])
        if len(values) != len(self.axes) or len(target) != len(self.axes):
            raise ValueError(f"{self.owner}: the state has {len(values)} axes, this controller {len(self.axes)}")
        self._values, self._target = values, target
