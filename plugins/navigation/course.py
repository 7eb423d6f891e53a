"""The course of the Navigation.AMCL service: planning and following the path (thesis §6.1.2, §7.4).

Given the estimate of each frame (plugins/navigation/amcl.py): plan on the Environment's map with
the A* planner when the goal is set, when the robot strays more than ``strayDistance`` from the
path, or when scan points fall on the path ahead (they become obstacles of a new plan; D152); take
a new plan when obstacles cleared make the way ``replanGain`` metres shorter; stop at the goal and
report ``arrived`` once the base has stopped (D109, D128); a map Object as goal is gone up to, short
of its outline and facing it, without counting it or scan points on it as obstacles (D260); once
reached, a heading the estimate moved off the goal's only makes the base turn on the spot (D255);
wait stopped for a localization and fail after ``localizeTimeout`` (D108). The ``status`` and
``path`` outputs are made here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from plugins.environment.planner import Unreachable

from .frames import Point, Pose, compose, inverse, polyline_length, project, remaining_length, transform_point, wrap
from .localizer import Localizer
from .object_goals import on_object, standoff_pose
from .routes import Routes, blocking


class NavigationCourse:
    """Planning and path following of :class:`plugins.navigation.amcl.AmclNavigation`, which sets these attributes."""

    params: dict[str, Any]
    laser: Pose
    routes: Routes
    localizer: Localizer | None
    goal_text: str
    goal: tuple[float, float, float | None] | None
    goal_object: str | None
    object_placed: bool
    phase: str
    reason: str
    plan: list[Point] | None
    target: Point | None
    segment: int
    path_id: int
    plan_length: float
    unlocalized_since: float | None
    stopped: bool
    settling: bool
    at_goal: bool
    turning: bool

    def _replan(self, start: Pose) -> None:
        """A new plan from ``start`` to the goal; an unreachable goal fails with the planner's reason."""
        assert self.goal is not None
        here = (start[0], start[1])
        if self.goal_object is not None and not self.object_placed:  # up to the object, from where the robot is
            p = self.params
            try:
                self.goal = standoff_pose(self.routes.model, self.routes.model.objects[self.goal_object], here,
                                          p["robotRadius"] + p["objectStandoff"], self.routes.footprint)
            except ValueError as refused:
                self.phase, self.reason, self.plan = "failed", str(refused), None
                return
            self.object_placed = True
        goal = (self.goal[0], self.goal[1])
        try:
            points = self.routes.plan(here, goal)
        except Unreachable as refused:
            self.phase, self.reason, self.plan = "failed", str(refused), None
            return
        self.plan, self.segment, self.path_id = points, 0, self.path_id + 1
        self.target = points[-1]  # the goal, or the free point standing in for it (goalEscape)
        self.plan_length = polyline_length(points)
        self.phase = "active"

    def _blocked(self, pose: Pose, hits: np.ndarray | None) -> list[Point]:
        """Scan points (``hits``) within the robot's radius of the next ``blockLookahead`` m of the path."""
        if hits is None or self.plan is None:
            return []
        self.segment, near, _ = project(self.plan, (pose[0], pose[1]), self.segment)
        p = self.params
        if self.goal_object is not None:  # the object gone up to is where the path ends, not in its way
            hits = hits[~on_object(hits, self.routes.model.objects[self.goal_object], p["objectStandoff"] + 0.05)]
        return blocking(self.plan, self.segment, near, hits, p["robotRadius"], p["blockLookahead"], p["blockPoints"])

    def _shorter(self, pose: Pose) -> None:
        """Scan obstacles went: take a new plan if it is ``replanGain`` shorter than the rest of this one."""
        assert self.goal is not None and self.plan is not None
        self.segment, near, _ = project(self.plan, (pose[0], pose[1]), self.segment)
        left = remaining_length(self.plan, self.segment, near)
        try:
            points = self.routes.plan((pose[0], pose[1]), (self.goal[0], self.goal[1]))
        except Unreachable:
            return  # the current plan stays (the next frame checks it as usual)
        if polyline_length(points) < left - self.params["replanGain"]:
            self.plan, self.segment, self.path_id = points, 0, self.path_id + 1
            self.target, self.plan_length = points[-1], polyline_length(points)

    def _unlocalized(self, now: float, why: str) -> None:
        """Wait (stopped) for a localization; fail after ``localizeTimeout``."""
        self.unlocalized_since = now if self.unlocalized_since is None else self.unlocalized_since
        self.plan = None
        self.phase = "planning"
        if now - self.unlocalized_since > self.params["localizeTimeout"]:
            self.phase, self.reason = "failed", f"no localization for {self.params['localizeTimeout']:g} s ({why})"

    def _navigate(self, pose: Pose, scan: Mapping[str, Any] | None, now: float) -> None:
        """Follow the plan from ``pose``: stop at the goal, replan when blocked, strayed or shorter (D128, D152)."""
        assert self.goal is not None
        gyaw = self.goal[2]
        target = self.target or (self.goal[0], self.goal[1])
        near = math.dist(pose[:2], target) <= self.params["tolerance"]
        self.settling = near and (gyaw is None or abs(wrap(gyaw - pose[2])) <= self.params["yawTolerance"])
        self.at_goal = self.at_goal or self.settling
        self.turning = near and self.at_goal and not self.settling
        if self.turning:  # reached, and the estimate's heading has moved off since: only turn (D255)
            self.phase = "active"
            return
        if self.settling:  # at the goal as the localization sees it: stop the base (an empty path) ...
            if self.stopped:  # ... and once its odometry says it has stopped, arrived
                self.phase, self.plan = "arrived", None
            else:
                self.phase = "active"
            return  # (following on, the base would chase the end point each re-anchoring moves: D128)
        assert self.localizer is not None
        hits = None if scan is None else self.localizer.endpoints(scan, pose)
        cleared = 0
        if scan is not None and hits is not None:
            cleared = self.routes.forget(scan, compose(pose, self.laser), hits, now)
        if self.plan is not None:
            self.segment, _, off = project(self.plan, (pose[0], pose[1]), self.segment)
            blocking = self._blocked(pose, hits)
            if blocking:
                self.routes.avoid(blocking, now)
                self.plan = None
            elif off > self.params["strayDistance"]:
                self.plan = None
            elif cleared:
                self._shorter(pose)
        if self.plan is None:
            self._replan(pose)

    def _status(self, pose: Pose | None) -> dict[str, Any]:
        """The ``status`` output (NavStatus): the goal, the state, the plan's length and what is left of it."""
        remaining = 0.0
        if self.plan is not None and pose is not None:
            self.segment, near, _ = project(self.plan, (pose[0], pose[1]), self.segment)
            remaining = remaining_length(self.plan, self.segment, near)
        elif self.phase in ("planning", "active") and self.goal is not None and pose is not None:
            remaining = math.dist(pose[:2], self.goal[:2])
        return {
            "goal": self.goal_text,
            "state": self.phase,
            "path_length": float(self.plan_length),
            "remaining": float(remaining),
            "reason": self.reason,
        }

    def _path(self) -> dict[str, Any]:
        """The rest of the plan in the odom frame (no points: stop)."""
        assert self.localizer is not None and self.goal is not None
        correction = self.localizer.correction
        points: list[list[float]] = []
        yaw = None
        planned = self.plan is not None or self.turning
        if self.phase == "active" and not self.settling and planned and correction is not None:
            to_odom = inverse(correction)
            odom_pose = self.localizer.odom
            rest = [] if self.plan is None else self.plan[self.segment + 1 :]
            start = [] if odom_pose is None else [[odom_pose[0], odom_pose[1]]]  # from the robot, in odom
            # turning: the robot's own spot, so the base only turns to the yaw; the few cm left to the
            # path's end would have it face them first, half a turn away (D255)
            points = start + ([] if self.turning else [list(transform_point(to_odom, p)) for p in rest])
            if self.goal[2] is not None:
                yaw = wrap(self.goal[2] - correction[2])
        return {
            "id": self.path_id,
            "goal": self.goal_text,
            "frame": "odom",
            "points": points,
            "yaw": yaw,
            "speed": float(self.params["speed"]),
        }
