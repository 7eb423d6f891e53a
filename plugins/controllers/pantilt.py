"""``controller.pan-tilt-position``: position control of a pan-tilt head (the Nao's HeadYaw/HeadPitch, §7.1, Table 7.2).

Inputs: the goal (role ``setpoint``) and the measured head angles (two ``measure`` inputs, pan
then tilt, or roles ``pan`` and ``tilt``). Outputs: the pan and the tilt position commands (rad),
in that order, for position-mode joints.

The goal is a ``PanTilt`` message. With ``target="angles"`` (default) its ``pan``/``tilt`` are the
head angles to reach; with ``target="image"`` they are the target's pixel column and row in the
camera image (``imageWidth`` × ``imageHeight``, horizontal field of view ``fov``), and the goal is
the measured head angles plus the pinhole angles of that pixel from the image centre: a target
right of the centre turns the head right (pan decreases: positive pan turns left, as HeadYaw), a
target below it tilts the head down (tilt increases, as HeadPitch).

Law, per axis: the goal is bounded to [``panMin``, ``panMax``] / [``tiltMin``, ``tiltMax``]; a
reference r moves toward it at ``kp``·(goal − r), at most ``maxSpeed`` rad/s, and never more than
``maxLead`` ahead of the measured angle (a blocked head does not leave the reference running
away). The command is r. ``future()`` continues the reference toward the goal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import ParamError, read_params
from runtime.verification.manifest import MAPPING, NUMBER, P, Params, Ports

from .common import check_state, clamp
from .multi import MultiOutputController, Row, field, input_roles, role_values


class PanTiltPosition(MultiOutputController):
    """Moves a pan-tilt head to a goal in angles or in the image, speed- and range-limited."""

    kind = "pan-tilt-position"
    PARAMS = Params(
        P("kp", 4.0, "Gain from the angle error to the reference's speed.", unit="1/s", above=0.0),
        P("maxSpeed", 1.0, "Largest speed of the reference.", unit="rad/s", above=0.0),
        P("maxLead", 0.3, "Largest distance of the reference ahead of the measured angle.", unit="rad", above=0.0),
        P("panMin", -math.inf, "Lowest pan angle commanded.", unit="rad"),
        P("panMax", math.inf, "Highest pan angle commanded.", unit="rad"),
        P("tiltMin", -math.inf, "Lowest tilt angle commanded.", unit="rad"),
        P("tiltMax", math.inf, "Highest tilt angle commanded.", unit="rad"),
        P("target", "angles", "What the goal's pan/tilt are: head angles, or the target's pixel in the image.",
          choices=("angles", "image")),
        P("imageWidth", 640, "Image width (target=image).", unit="px", min=1),
        P("imageHeight", 480, "Image height (target=image).", unit="px", min=1),
        P("fov", 1.0, "Horizontal field of view of the camera (target=image).", unit="rad", above=0.0, below=math.pi),
    )
    PORTS = Ports(inputs={"setpoint": MAPPING, "*": NUMBER}, outputs={"*": NUMBER})  # a PanTilt-like goal

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record, outputs=2)
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        self.limits = ((values["panMin"], values["panMax"]), (values["tiltMin"], values["tiltMax"]))
        for axis, (low, high) in zip(("pan", "tilt"), self.limits, strict=True):
            if not low < high:
                raise ParamError(f"{self.owner}: parameter '{axis}Min' = {low} must be less than '{axis}Max' = {high}")
        roles = [r for r in input_roles(record) if r != "setpoint"]
        if sorted(roles) == ["pan", "tilt"]:
            self.roles: tuple[str, ...] = ("pan", "tilt")
        elif roles == ["measure", "measure"]:
            self.roles = ("measure",)
        else:
            raise ParamError(
                f"{self.owner} reads the measured pan and tilt: two inputs with role 'measure' (pan first) "
                f"or roles 'pan' and 'tilt', not {', '.join(roles) or 'none'}"
            )
        self.kp: float = values["kp"]
        self.max_speed: float = values["maxSpeed"]
        self.max_lead: float = values["maxLead"]
        self.image = values["target"] == "image"
        self.centre = (values["imageWidth"] / 2.0, values["imageHeight"] / 2.0)
        self.focal = self.centre[0] / math.tan(values["fov"] / 2.0)  # pixels
        self._reference: list[float] | None = None
        self._goal: list[float] | None = None
        self._setpoint: Any = None

    def measured(self, inputs: Mapping[str, Any]) -> tuple[float, float]:
        """The measured (pan, tilt)."""
        if self.roles == ("pan", "tilt"):
            return float(inputs["pan"]), float(inputs["tilt"])
        values = role_values(inputs, "measure")
        if len(values) != 2:
            raise KeyError(f"{self.owner}: expected inputs 'measure[0]' and 'measure[1]', got {sorted(inputs)}")
        return float(values[0]), float(values[1])

    def goal(self, setpoint: Any, measured: tuple[float, float]) -> list[float]:
        """The bounded goal angles for a ``PanTilt`` set point."""
        pan = field(setpoint, "pan", owner=self.owner, what="goal")
        tilt = field(setpoint, "tilt", owner=self.owner, what="goal")
        if self.image:
            pan = measured[0] - math.atan((pan - self.centre[0]) / self.focal)
            tilt = measured[1] + math.atan((tilt - self.centre[1]) / self.focal)
        return [clamp(v, low, high) for v, (low, high) in zip((pan, tilt), self.limits, strict=True)]

    def _advance(self, reference: list[float], goal: list[float], dt: float) -> list[float]:
        moved = []
        for r, g, (low, high) in zip(reference, goal, self.limits, strict=True):
            speed = clamp(self.kp * (g - r), -self.max_speed, self.max_speed)
            moved.append(clamp(r + speed * dt, low, high))
        return moved

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Pan and tilt commands: the reference one period further toward the goal (see the module docstring)."""
        dt = dt if dt > 0.0 else self.record.period
        measured = self.measured(inputs)
        if self._reference is None:
            self._reference = [clamp(m, low, high) for m, (low, high) in zip(measured, self.limits, strict=True)]
        setpoint = inputs.get("setpoint")
        if setpoint is not None and setpoint != self._setpoint:  # a held image target must not move the goal again
            self._goal, self._setpoint = self.goal(setpoint, measured), setpoint
        goal = self._goal if self._goal is not None else list(self._reference)  # no goal yet: hold
        moved = self._advance(self._reference, goal, dt)
        self._reference = [clamp(r, m - self.max_lead, m + self.max_lead) for r, m in zip(moved, measured, strict=True)]
        return tuple(self._reference)

    def future_outputs(self) -> list[Row]:
        """The reference continued toward the goal over the horizon (empty before the first step)."""
        if self._reference is None:
            return []
        rows, reference = [], list(self._reference)
        goal = self._goal if self._goal is not None else reference
        for _ in range(self.record.horizon):
            reference = self._advance(reference, goal, self.record.period)
            rows.append(tuple(reference))
        return rows

    def bumpless(self, output: Any) -> None:
        """Start the reference from ``output`` (a pan-tilt pair), or from the measured angles."""
        row = self.as_row(output, 2)
        self._reference = None if row is None else list(row)

    def state(self) -> dict[str, Any]:
        """Reference and goal (code delegation, §3.1.2.6)."""
        return {"kind": self.kind, "reference": self._reference, "goal": self._goal}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a pan-tilt-position controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("reference", "goal"))
        self._reference = None if state["reference"] is None else [float(v) for v in state["reference"]]
        self._goal = None if state["goal"] is None else [float(v) for v in state["goal"]]
