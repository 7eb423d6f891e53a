"""Control laws of the Mobile Base's Displacement service (thesis §7.1, Table 7.1 "Speed").

All run on odometry at the service rate and return a velocity command (linear m/s, angular rad/s)
before the acceleration limits of :class:`Limiter`.

- :class:`PathFollower`: pure pursuit (Coulter 1992) on a polyline. The carrot is ``lookahead``
  metres further along the path than the robot's projection on it; the curvature toward it is
  κ = 2·sin(α)/d (α its bearing, d its distance). The speed is the top speed, capped so the
  robot can still stop at the path's end braking at half the limit (v ≤ √(a·remaining)) and
  so that |κ·v| stays within ``max_angular``; a carrot more than ``turn_in_place`` rad off the heading is first faced by
  turning in place (the Kobuki is differential drive). A new path is first faced to within
  ``face`` rad, turning in place (D237): a re-plan after a bumper hit starts beside the obstacle, and
  an arc toward a carrot up to ``turn_in_place`` off swept the base's front into it again. At the
  end (within ``tolerance``) the robot turns in place to the path's final yaw, if it has one.
- :class:`RelativeMove`: rotate / drive / rotate to a goal pose fixed in the odometry frame when
  the goal arrived. A goal behind the robot (BACK's) is driven backwards rather than turned to.
  While driving, the heading is kept on the goal point by a proportional term, and the speed
  follows the same stopping profile; the drive ends when the goal is less than a fifth of
  ``tolerance`` ahead or has been passed (its projection on the heading changes sign).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from .frames import Point, Pose, along, project, relative, remaining_length, wrap

Command = tuple[float, float]
STOP: Command = (0.0, 0.0)
FINISH = 0.2
"""A relative move drives until the goal is this share of the tolerance ahead (then brakes)."""


@dataclass(frozen=True)
class Gains:
    """Speeds, accelerations and tolerances shared by the control laws."""

    max_angular: float = 1.5
    accel: float = 0.5
    angular_accel: float = 2.5
    lookahead: float = 0.35
    heading_gain: float = 2.5
    turn_in_place: float = 1.0
    face: float = 0.35
    tolerance: float = 0.03
    yaw_tolerance: float = 0.03
    min_speed: float = 0.03
    min_angular: float = 0.15


def stopping_speed(distance: float, gains: Gains, top: float) -> float:
    """A speed (≤ ``top``) from which the robot stops within ``distance`` m braking at half ``accel``.

    Planning the stop at half the limit leaves the other half for the command's delay (one
    period, and the base's own loops): braking at the limit overshot by the distance of a period.
    """
    return min(top, max(gains.min_speed, math.sqrt(gains.accel * max(0.0, distance))))


def turn(error: float, gains: Gains) -> float:
    """Angular speed turning in place to cancel ``error`` (rad): proportional, stopping-limited, with a floor."""
    speed = min(gains.max_angular, gains.heading_gain * abs(error), math.sqrt(2.0 * gains.angular_accel * abs(error)))
    return math.copysign(max(speed, gains.min_angular), error)


class Limiter:
    """Bounds the change of the command to ``accel`` (m/s²) and ``angular_accel`` (rad/s²)."""

    def __init__(self, gains: Gains) -> None:
        self.gains = gains
        self.last: Command = STOP

    def __call__(self, wanted: Command, dt: float) -> Command:
        """The command nearest ``wanted`` reachable from the last one in ``dt`` seconds."""
        dv, dw = self.gains.accel * dt, self.gains.angular_accel * dt
        v = min(max(wanted[0], self.last[0] - dv), self.last[0] + dv)
        w = min(max(wanted[1], self.last[1] - dw), self.last[1] + dw)
        self.last = (v, w)
        return self.last

    def reset(self) -> None:
        """Start again from rest (the base was stopped by something else)."""
        self.last = STOP


class PathFollower:
    """Pure pursuit along ``points`` (odom frame) with the final heading ``yaw`` (None: any)."""

    def __init__(self, points: Sequence[Point], yaw: float | None, speed: float, gains: Gains) -> None:
        self.points, self.yaw, self.speed, self.gains = list(points), yaw, speed, gains
        self.segment = 0
        self.remaining = remaining_length(self.points, 0, self.points[0]) if self.points else 0.0
        self.done = not self.points
        self.aligning = False
        self.facing = True  # a new path: face its carrot before driving (D237)

    def update(self, points: Sequence[Point], yaw: float | None, speed: float) -> None:
        """The same path re-anchored (Navigation's new map→odom correction): keep going on it."""
        self.points, self.yaw, self.speed = list(points), yaw, speed
        self.segment = 0
        self.done = not self.points

    def state(self) -> dict[str, Any]:
        """Where the follower is (msgpack-able), for :meth:`from_state`."""
        return {"points": [list(p) for p in self.points], "yaw": self.yaw, "speed": self.speed,
                "segment": self.segment, "remaining": self.remaining, "done": self.done, "aligning": self.aligning,
                "facing": self.facing}

    @classmethod
    def from_state(cls, state: Mapping[str, Any], gains: Gains) -> PathFollower:
        """A follower where :meth:`state` left one (a partition restarted, §3.1.2.3)."""
        made = cls([(float(x), float(y)) for x, y in state["points"]], state["yaw"], float(state["speed"]), gains)
        made.segment, made.remaining = int(state["segment"]), float(state["remaining"])
        made.done, made.aligning = bool(state["done"]), bool(state["aligning"])
        made.facing = bool(state.get("facing", False))
        return made

    def command(self, pose: Pose) -> Command:
        """The velocity command for the robot at ``pose`` (odometry frame): pure pursuit, then the final yaw."""
        g = self.gains
        if self.done:
            return STOP
        here = (pose[0], pose[1])
        self.segment, near, _ = project(self.points, here, min(self.segment, max(0, len(self.points) - 2)))
        self.remaining = remaining_length(self.points, self.segment, near)
        end = self.points[-1]
        to_end = math.dist(here, end)
        if self.aligning or to_end <= g.tolerance or (self.remaining <= g.tolerance and to_end <= 2 * g.tolerance):
            # at the end: only the heading is left (a pose goal), turning in place
            self.aligning = to_end <= 3 * g.tolerance  # pushed off the end: follow again
            error = 0.0 if self.yaw is None else wrap(self.yaw - pose[2])
            if abs(error) <= g.yaw_tolerance:
                self.done = True
                return STOP
            return 0.0, turn(error, g)
        carrot = along(self.points, self.segment, near, g.lookahead)
        if math.dist(here, carrot) < 1e-6:
            carrot = end
        local = relative(pose, (carrot[0], carrot[1], 0.0))
        alpha = math.atan2(local[1], local[0])
        if self.facing and abs(alpha) > g.face:
            return 0.0, turn(alpha, g)
        self.facing = False
        if abs(alpha) > g.turn_in_place:
            return 0.0, turn(alpha, g)
        distance = max(math.hypot(local[0], local[1]), 1e-6)
        curvature = 2.0 * math.sin(alpha) / distance
        v = stopping_speed(min(self.remaining, to_end) if self.remaining > 0 else to_end, g, self.speed)
        if abs(curvature * v) > g.max_angular:
            v = g.max_angular / abs(curvature)
        return v, curvature * v


class RelativeMove:
    """Rotate / drive / rotate to ``goal`` (odom frame), backwards when the goal lies behind."""

    def __init__(self, start: Pose, goal: Pose, speed: float, gains: Gains) -> None:
        self.goal, self.speed, self.gains = goal, speed, gains
        local = relative(start, goal)
        self.total = math.hypot(local[0], local[1])
        self.backwards = local[0] < 0 and abs(local[1]) < -local[0]  # mostly behind: reverse into it
        self.phase = "face" if self.total > gains.tolerance else "align"
        self.remaining = self.total

    def state(self) -> dict[str, Any]:
        """Where the move is (msgpack-able), for :meth:`from_state`."""
        return {"goal": list(self.goal), "speed": self.speed, "total": self.total, "backwards": self.backwards,
                "phase": self.phase, "remaining": self.remaining, "yaw_tolerance": self.gains.yaw_tolerance}

    @classmethod
    def from_state(cls, state: Mapping[str, Any], gains: Gains) -> RelativeMove:
        """A move where :meth:`state` left one (a partition restarted, §3.1.2.3)."""
        x, y, yaw = (float(v) for v in state["goal"])
        if "yaw_tolerance" in state:  # the goal's own (Move2D ``yaw_tolerance``)
            gains = replace(gains, yaw_tolerance=float(state["yaw_tolerance"]))
        made = cls((x, y, yaw), (x, y, yaw), float(state["speed"]), gains)
        made.total, made.backwards = float(state["total"]), bool(state["backwards"])
        made.phase, made.remaining = str(state["phase"]), float(state["remaining"])
        return made

    def _bearing(self, pose: Pose) -> tuple[float, float]:
        """(distance along the heading, bearing error) of the goal point, for the driving direction."""
        local = relative(pose, self.goal)
        if self.backwards:
            return -local[0], wrap(math.atan2(local[1], local[0]) - math.pi)
        return local[0], math.atan2(local[1], local[0])

    def command(self, pose: Pose) -> Command:
        """The velocity command for the robot at ``pose`` (odometry frame): face, drive, then align."""
        g = self.gains
        self.remaining = math.dist(pose[:2], self.goal[:2])
        if self.phase == "face":
            _, error = self._bearing(pose)
            if abs(error) > g.yaw_tolerance * 2 and self.remaining > g.tolerance:
                return 0.0, turn(error, g)
            self.phase = "drive"
        if self.phase == "drive":
            ahead, error = self._bearing(pose)
            if ahead > FINISH * g.tolerance:  # drive on to a fraction of the tolerance: it ends short otherwise
                v = stopping_speed(ahead, g, self.speed)
                w = max(-g.max_angular, min(g.max_angular, g.heading_gain * error)) if self.remaining > 0.1 else 0.0
                return (-v if self.backwards else v), w
            self.phase = "align"
        error = wrap(self.goal[2] - pose[2])
        if abs(error) <= g.yaw_tolerance:
            self.phase = "done"
            return STOP
        return 0.0, turn(error, g)

    @property
    def done(self) -> bool:
        """Whether the move has reached its goal pose."""
        return self.phase == "done"
