"""``controller.joint-trajectory``: plays arm trajectories and predefined poses on position joints (§7.4.2, Fig. 7.20).

Params: ``joints`` (the joint names, in the order of the outputs), ``maxVelocity`` (rad/s, one
value or one per joint), ``interpolation`` (``cubic``: rest to rest, peak speed 1.5·Δq/T;
``linear``: constant speed), ``poses`` (predefined poses: ``name: q1 q2 …; name: …``),
``lowerLimits``/``upperLimits`` (rad, one per joint) and ``tolerance``.

Inputs: role ``setpoint`` — a ``JointTrajectory`` (``joint_names``, ``points`` with ``positions``
and ``time_from_start``), an ``ArmGoal`` (its ``pose`` names one of ``poses``; its ``speed``, 0–1,
scales the velocities; a goal for ``group="gripper"`` moves only the joints whose name contains
"gripper") or a plain list of positions; role ``measure`` — a ``JointState`` or a list of
positions in ``joints`` order. Outputs: one position command per joint, then, if an ``<Output>``
has ``role="status"``, an ``ArmStatus`` (``active`` false on an error such as an unknown pose).

A new set point is planned from the current command (or the measured positions at start): one
segment per waypoint, each lasting max(its time_from_start step, c·|Δq_j|/v_j over the joints),
c = 1.5 for cubic and 1 for linear, so no joint exceeds its velocity limit. Targets are bounded to
the joint limits. The set point is held as long as it is the same message. ``future()`` samples
the rest of the plan, so the actuators can finish it if the controller's inputs are lost.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import ParamError, read_params
from runtime.verification.manifest import ANY, MAPPING, NUMBER, REQUIRED, P, Params, Ports

from .common import check_state, clamp
from .multi import MultiOutputController, Row, numbers

Segment = tuple[list[float], list[float], float]  # start, end, duration


class JointTrajectory(MultiOutputController):
    """Velocity-limited interpolation of joint set points to trajectories and predefined poses."""

    kind = "joint-trajectory"
    PARAMS = Params(
        P("joints", REQUIRED, "The joint names, space-separated, in the order of the outputs.", type=str),
        P("maxVelocity", "1.0", "Velocity limit of each joint (one value for all, or one per joint).", unit="rad/s"),
        P("interpolation", "cubic", "Profile of each segment: cubic (rest to rest) or linear.",
          choices=("cubic", "linear")),
        P("poses", "", "Predefined poses: 'name: q1 q2 …' separated by ';' (one angle per joint).", unit="rad"),
        P("lowerLimits", "", "Lowest position of each joint (empty: none).", unit="rad"),
        P("upperLimits", "", "Highest position of each joint (empty: none).", unit="rad"),
        P("tolerance", 0.01, "Largest distance from the goal at which a pose counts as reached.", unit="rad",
          above=0.0),
    )
    PORTS = Ports(inputs={"*": ANY}, outputs={"status": MAPPING, "*": NUMBER})  # status: an ArmStatus-like message

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        self.joints: list[str] = values["joints"].split()
        n = len(self.joints)
        if not n or len(set(self.joints)) != n:
            raise ParamError(f"{self.owner}: parameter 'joints' must name each joint once")
        roles = [port.role for port in record.outputs]
        self.status_index = roles.index("status") if "status" in roles else None
        if len(record.outputs) - (self.status_index is not None) != n:
            raise ParamError(f"{self.owner}: {n} joints need {n} <Output> (plus one with role 'status'), "
                             f"got {len(record.outputs)}")
        self.velocity = numbers(values["maxVelocity"], name="maxVelocity", owner=self.owner, count=n)
        if any(not v > 0.0 for v in self.velocity):
            raise ParamError(f"{self.owner}: parameter 'maxVelocity' must be greater than 0 for every joint")
        self.lower = numbers(values["lowerLimits"] or "-inf", name="lowerLimits", owner=self.owner, count=n)
        self.upper = numbers(values["upperLimits"] or "inf", name="upperLimits", owner=self.owner, count=n)
        if any(not lo < hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ParamError(f"{self.owner}: each lower limit must be less than its upper limit")
        self.poses: dict[str, list[float]] = {}
        for entry in filter(None, (e.strip() for e in values["poses"].split(";"))):
            name, sep, angles = entry.partition(":")
            if not sep or not name.strip():
                raise ParamError(f"{self.owner}: parameter 'poses': {entry!r} is not 'name: q1 q2 …'")
            self.poses[name.strip()] = numbers(angles, name=f"poses ({name.strip()})", owner=self.owner, count=n)
        self.factor = 1.5 if values["interpolation"] == "cubic" else 1.0
        self.tolerance: float = values["tolerance"]
        self._command: list[float] | None = None
        self._plan: list[Segment] = []
        self._elapsed = 0.0
        self._setpoint: Any = None
        self._pose = ""  # the pose being reached (or reached)
        self._error = ""

    # ------------------------------------------------------------------ planning

    def _bounded(self, target: Sequence[float]) -> list[float]:
        return [clamp(float(q), lo, hi) for q, lo, hi in zip(target, self.lower, self.upper, strict=True)]

    def plan(self, start: list[float], waypoints: list[tuple[list[float], float]], speed: float = 1.0) -> None:
        """Segments from ``start`` through ``waypoints`` (target, minimum duration), velocity-limited."""
        self._plan, self._elapsed = [], 0.0
        for target, minimum in waypoints:
            end = self._bounded(target)
            needed = max(self.factor * abs(e - s) / (v * speed) for s, e, v in zip(start, end, self.velocity,
                                                                                  strict=True))
            self._plan.append((start, end, max(needed, minimum)))
            start = end

    def _waypoints(self, setpoint: Any, current: list[float]) -> tuple[list[tuple[list[float], float]], float]:
        """The waypoints of a set point and its speed scaling."""
        if isinstance(setpoint, Mapping) and "points" in setpoint:
            names = list(setpoint.get("joint_names") or self.joints)
            unknown = [name for name in names if name not in self.joints]
            if unknown:
                raise ValueError(f"trajectory names joints {', '.join(unknown)} this controller does not drive")
            waypoints, previous, last = [], 0.0, list(current)
            for point in setpoint["points"]:
                target = list(last)
                for name, q in zip(names, point["positions"], strict=True):
                    target[self.joints.index(name)] = float(q)
                stamp = float(point.get("time_from_start", 0.0))
                waypoints.append((target, max(0.0, stamp - previous)))
                previous, last = max(previous, stamp), target
            return waypoints, 1.0
        if isinstance(setpoint, Mapping) and "pose" in setpoint:
            name = str(setpoint["pose"])
            if name not in self.poses:
                raise ValueError(f"unknown pose {name!r} (defined: {', '.join(self.poses) or 'none'})")
            target = list(self.poses[name])
            if setpoint.get("group") == "gripper":  # a gripper goal leaves the arm where it is, and back
                target = [t if "gripper" in j else c for j, t, c in zip(self.joints, target, current, strict=True)]
            elif setpoint.get("group") == "arm":
                target = [c if "gripper" in j else t for j, t, c in zip(self.joints, target, current, strict=True)]
            speed = float(setpoint.get("speed") or 1.0)
            self._pose = name
            return [(target, 0.0)], clamp(speed, 1e-3, 1.0)
        return [([float(q) for q in setpoint], 0.0)], 1.0

    # ------------------------------------------------------------------ control

    def measured(self, measure: Any) -> list[float]:
        """Joint positions, in ``joints`` order, from a JointState or a list."""
        if isinstance(measure, Mapping):
            names, positions = list(measure.get("name") or []), list(measure["position"])
            if not names:  # a sensor's JointState names nothing: its positions are in ``joints`` order
                return [float(q) for q in positions[: len(self.joints)]]
            by_name = dict(zip(names, positions, strict=True))
            return [float(by_name[j]) for j in self.joints]
        return [float(q) for q in measure]

    def _sample(self, elapsed: float) -> list[float]:
        for start, end, duration in self._plan:
            if elapsed < duration:
                tau = elapsed / duration
                s = tau if self.factor == 1.0 else tau * tau * (3.0 - 2.0 * tau)
                return [a + (b - a) * s for a, b in zip(start, end, strict=True)]
            elapsed -= duration
        return list(self._plan[-1][1]) if self._plan else list(self._command or [])

    @property
    def remaining(self) -> float:
        """Seconds left in the plan."""
        return max(0.0, sum(d for _, _, d in self._plan) - self._elapsed)

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """The joint commands one period along the plan, with the ``ArmStatus`` if an output has that role.

        A new set point is planned from the current command; a bad one empties the plan and is reported.

        Raises:
            KeyError: there is no ``measure`` input to start from.
        """
        dt = dt if dt > 0.0 else self.record.period
        measure = inputs.get("measure")
        if self._command is None:
            if measure is None:
                raise KeyError(f"{self.owner}: no 'measure' input to start from")
            self._command = self._bounded(self.measured(measure))
        setpoint = inputs.get("setpoint")
        if setpoint is not None and setpoint != self._setpoint:
            self._setpoint, self._pose = setpoint, ""
            try:
                waypoints, speed = self._waypoints(setpoint, self._command)
                self.plan(list(self._command), waypoints, speed)
                self._error = ""
            except (ValueError, KeyError, TypeError) as exc:
                self._plan, self._error = [], f"{self.owner}: bad set point: {exc}"
        else:
            self._elapsed += dt
        self._command = self._sample(self._elapsed)
        return self._row(self._command, measure)

    def _row(self, command: list[float], measure: Any) -> Row:
        row: list[Any] = list(command)
        if self.status_index is not None:
            reached = self.remaining == 0.0
            if reached and measure is not None:
                error = max(abs(c - m) for c, m in zip(command, self.measured(measure), strict=True))
                reached = error <= self.tolerance
            pose = self._pose if reached else ""
            status = {"stamp": time.time(), "active": not self._error, "pose": pose, "error": self._error}
            row.insert(self.status_index, status)
        return tuple(row)

    def future_outputs(self) -> list[Row]:
        """The rest of the plan sampled over the horizon (joint commands only; empty before the first step)."""
        if self._command is None:
            return []
        rows = []
        for k in range(1, self.record.horizon + 1):
            row: list[Any] = self._sample(self._elapsed + k * self.record.period)
            if self.status_index is not None:
                row.insert(self.status_index, None)  # no stored statuses: only joint commands are played
            rows.append(tuple(row))
        return rows

    def bumpless(self, output: Any) -> None:
        """Restart from the measured positions at the next step."""
        self._command = None  # restart from the measured positions
        self._plan, self._elapsed = [], 0.0

    def state(self) -> dict[str, Any]:
        """Command, plan, time along it and pose (code delegation, §3.1.2.6)."""
        return {
            "kind": self.kind,
            "command": self._command,
            "plan": [[list(s), list(e), d] for s, e, d in self._plan],
            "elapsed": self._elapsed,
            "pose": self._pose,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a joint-trajectory controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("command", "plan", "elapsed", "pose"))
        self._command = None if state["command"] is None else [float(v) for v in state["command"]]
        self._plan = [([float(v) for v in s], [float(v) for v in e], float(d)) for s, e, d in state["plan"]]
        self._elapsed = float(state["elapsed"])
        self._pose = str(state["pose"])
