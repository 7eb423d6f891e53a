"""``plugin.amcl-navigation``: the Navigation resource's AMCL service (thesis §6.2, §7.4; Tables 7.1, 7.8).

Inputs (a mapping): ``scan`` (LaserScan of LaserSensor.Scan) and ``odom`` (Odometry of
MobileBase.Displacement). Each frame (0.8 s in the use case, Table 7.8):

1. localize: one step of Algorithm 3 (``filter=reliability``) or of the AMCL-like baseline
   (``filter=mcl``) on the odometry increment and the scan (plugins/navigation/localizer.py),
   without the beams that hit something the map lacks (``unmapped``, D235);
2. plan on the Environment's map with the A* planner of plugins/environment (§6.1.2), the robot's
   footprint inflated by ``inflation``: when the goal is set, when the robot strays more than
   ``strayDistance`` from the path, or when scan points fall on the path ahead (they become
   obstacles of a new plan; the map's own obstacles are at least the inflated radius away); those
   obstacles go when a later beam sees through them or after ``obstacleTimeout`` s unseen (D152),
   and the robot takes a new plan when that makes the way ``replanGain`` metres shorter;
3. publish ``pose`` (PoseEstimate: pose, covariance, dispersion), ``status`` (NavStatus) and
   ``path`` (Path2D: the rest of the plan in the odom frame through the current map→odom
   correction, which MobileBase.Displacement follows on odometry until the next frame), and for the
   live view and the recording ``particles`` (ParticleCloud: ≤ ``cloudSize`` particles) and ``zoom``
   (ZoomArea: the ``<ZoomMap>`` area following the estimate), plugins/navigation/live.py, D215.

The goal is the service Parameter ``goal`` (Table 7.1 "Goal", via :meth:`apply_service_parameters`):
an Area of the Environment (its centroid, any heading) or ``"x y yaw"`` in the map frame. States:
``planning`` (no plan yet, or waiting, stopped, for an estimate whose position uncertainty
√(σx² + σy²) is within ``maxUncertainty``: decision D108), ``active``, ``arrived`` (the base has
stopped within ``tolerance``, and ``yawTolerance`` for a pose goal: the path is then empty, which
keeps it stopped; D109), ``failed`` with a ``reason``: the planner's (unreachable goal: it collides
with an obstacle, lies outside the map, or no free path joins it) or no localization for
``localizeTimeout`` seconds. A start inside an inflated obstacle (after a close approach) is left
by the nearest free point within ``escape`` metres, a goal inside one is replaced by the nearest
free point within ``goalEscape`` (decision D107). Top-level ``dispersion`` is the
"Localization Dispersion" measure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from ckmconf.model.environment import Environment
from ckmconf.model.resources import Plugin
from plugins.environment.geometry import Footprint
from plugins.environment_file import environment_of
from plugins.localization.estimate import Estimate
from plugins.localization.raster import GridMap
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, REQUIRED, P, Params, Ports, fixed_numbers

from .course import NavigationCourse
from .frames import (
    Point,
    Pose,
    mapping,
    parse_pose,
    pose_message,
    pose_of,
    wrap,
)
from .live import NavigationZoom, particle_cloud
from .localizer import FILTERS, Localizer
from .obstacles import ScanObstacles
from .routes import Routes

INPUTS = ("scan", "odom")
RANGE_MAX = 8.0
"""Longest laser range the filters' models assume (m): the beams' own validity comes from each scan's
range_min/range_max (invalid ones reach the filters as +inf), so this only scales the likelihood
field's random-reading term, as AMCL's laser_max_range does."""
STOPPED = 0.02
"""The base is stopped when its odometry's speeds (m/s, rad/s) are below this."""


def uncertainty(estimate: Estimate) -> float:
    """√(σx² + σy²) of an estimate's covariance: how far off its position may be (m)."""
    covariance = np.asarray(estimate.covariance, dtype=np.float64)
    return math.sqrt(max(0.0, float(covariance[0, 0] + covariance[1, 1])))


class AmclNavigation(NavigationCourse, ProcessingPlugin):
    """``plugin.amcl-navigation``: localization, planning and the path of the Navigation.AMCL service."""

    PORTS = Ports(inputs={"scan": MAPPING, "odom": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "navigation"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {  # beyond the interface's pose and status
        "path": ("id", "goal", "frame", "points", "yaw", "speed"),
        "particles": ("stamp", "frame", "total", "x", "y", "yaw", "weight"),
        "zoom": ("stamp", "frame", "mode", "x", "y", "width", "depth", "height", "reason", "since", "objects",
                 "avoided"),
    }
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("environment", REQUIRED, "XML file holding the system's <Environment> (the map), relative to the "
          "configuration file.", type=str, file=ENVIRONMENT_FILE),
        P("filter", "reliability", "Algorithm 3 ('reliability') or the AMCL-like baseline ('mcl').", choices=FILTERS),
        P("particles", 2000, "Number of particles.", min=10),
        P("beams", 60, "Beams of each scan used by the filter, evenly spread.", min=3),
        P("resolution", 0.05, "Cell size of the localization grid.", unit="m", above=0.0),
        P("laserPose", REQUIRED, "The laser's mount 'x y yaw' in the robot frame (m, m, rad): the URDF's laser "
          "joint.", type=str, numbers=(3,), form="'x y yaw'"),
        P("laserHeight", REQUIRED, "Height of the scan plane above the floor: the map obstacles it cuts.", unit="m",
          type=float, min=0.0),
        P("initialPose", "", "Start: 'x y yaw' or an Area name (its centroid); empty: global localization."),
        P("initialSpread", "0.3 0.2", "Standard deviations 'metres radians' of the initial particles.",
          numbers=(2,), form="'metres radians'"),
        P("goal", "", "Goal until the service Parameter 'goal' sets one: 'x y yaw', an Area's name or an "
          "Object's name."),
        P("objectStandoff", 0.1, "Gap left between the robot's footprint and a map Object given as goal.", unit="m",
          min=0.0),
        P("robotRadius", REQUIRED, "Radius of the robot's round footprint (the URDF base's half width).", unit="m",
          type=float, above=0.0),
        P("robotHeight", REQUIRED, "Height of the robot: objects above it do not obstruct it.", unit="m",
          type=float, above=0.0),
        P("inflation", 0.02, "Clearance added to the footprint when planning.", unit="m", min=0.0),
        P("planResolution", 0.1, "Cell size of the A* grid.", unit="m", above=0.0),
        P("speed", 0.3, "Speed asked of the Mobile Base along the path.", unit="m/s", above=0.0),
        P("tolerance", 0.15, "Arrived within this distance of the goal.", unit="m", above=0.0),
        P("yawTolerance", 0.2, "And within this heading of a pose goal.", unit="rad", above=0.0),
        P("maxUncertainty", 0.35, "Position uncertainty √(σx² + σy²) of the estimate above which the robot does not "
          "drive.", unit="m", above=0.0),
        P("localizeTimeout", 10.0, "Fail after this long without a good localization.", unit="s", above=0.0),
        P("strayDistance", 0.5, "Replan when the robot is this far from the path.", unit="m", above=0.0),
        P("blockLookahead", 1.5, "Scan points on this much of the path ahead block it.", unit="m", above=0.0),
        P("blockPoints", 3, "Scan points on the path ahead that make it blocked.", min=1),
        P("obstacleTimeout", 30.0, "Forget a scan obstacle not seen again for this long (0: only when seen "
          "through).", unit="s", min=0.0),
        P("obstacleClearance", 0.1, "Extra clearance the plan keeps from scan obstacles (D238).", unit="m", min=0.0),
        P("clearMargin", 0.1, "A beam reaching this far beyond a scan obstacle's point clears it.", unit="m", min=0.0),
        P("replanGain", 0.2, "After scan obstacles cleared, take a new plan if it is this much shorter.", unit="m",
          min=0.0),
        P("escape", 0.6, "How far a start inside an inflated obstacle looks for free space.", unit="m", min=0.0),
        P("goalEscape", 0.3, "How far a goal inside an inflated obstacle may move to free space.", unit="m", min=0.0),
        P("unmapped", 0.3, "A beam this much shorter than the map's ray from the predicted pose, ending this far "
          "from any mapped obstacle, hit something the map lacks: the filter ignores it (0: use every beam).",
          unit="m", min=0.0),
        P("seed", 0, "Random seed of the filter.", min=0),
        P("cloudSize", 200, "Particles in each published ParticleCloud (0: none).", min=0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p, owner = self.params, self.owner
        x, y, yaw = fixed_numbers(p["laserPose"], 3, "laserPose", owner)
        self.laser: Pose = (x, y, yaw)
        sigma_xy, sigma_yaw = fixed_numbers(p["initialSpread"], 2, "initialSpread", owner)
        if sigma_xy < 0 or sigma_yaw < 0:
            raise ParamError(f"{owner}: parameter 'initialSpread' = {p['initialSpread']!r} must not be negative")
        self.spread = (sigma_xy, sigma_yaw)
        base = config_dir(record)
        self.environment_file = base / p["environment"]
        self.env: Environment | None = None
        self.localizer: Localizer | None = None
        self.zoom: NavigationZoom | None = None
        self.goal_text = ""
        self.goal: tuple[float, float, float | None] | None = None
        self.goal_object: str | None = None  # a map Object as goal: its standoff pose is placed at the first plan
        self.object_placed = False
        self._pending_goal: str | None = p["goal"] or None
        self.phase, self.reason = "planning", ""
        self.plan: list[Point] | None = None
        self.target: Point | None = None
        self.segment = 0
        self.path_id = 0
        self.plan_length = 0.0
        self.unlocalized_since: float | None = None
        self.stopped = True
        self.settling = False  # at the goal, the path emptied: waiting for the base to stop
        self.at_goal = False  # the goal was reached once (settling): after that, a heading off only turns (D255)
        self.turning = False

    # ------------------------------------------------------------------ set-up and goals

    def setup(self) -> None:
        """Read the Environment, rasterise it for the filter, build the planner, place the prior."""
        if self.env is not None:
            return
        self.env = env = environment_of(self.environment_file, self.owner)
        p = self.params
        footprint = Footprint.round(p["robotRadius"] + p["inflation"], p["robotHeight"])
        self.routes = Routes(env, footprint, p["planResolution"], p["escape"], p["goalEscape"],
                             ScanObstacles(margin=p["clearMargin"], timeout=p["obstacleTimeout"],
                                           clearance=p["obstacleClearance"]))
        self.model = self.routes.model
        self.zoom = None if env.zoom is None else NavigationZoom(self.model, env.zoom)
        grid = GridMap.from_environment(env, p["resolution"], scan_height=p["laserHeight"])
        self.localizer = Localizer(grid, p["filter"], particles=p["particles"], beams=p["beams"], laser=self.laser,
                                   range_max=RANGE_MAX, seed=p["seed"], owner=self.owner, unmapped=p["unmapped"])
        initial = self._place(p["initialPose"], "parameter 'initialPose'") if p["initialPose"].strip() else None
        self.localizer.reset(None if initial is None else (initial[0], initial[1], initial[2] or 0.0),
                             self.spread if initial is None or initial[2] is not None else (self.spread[0], math.pi))
        if self._pending_goal is not None:
            self.apply_service_parameters({"goal": self._pending_goal})

    def _place(self, text: str, where: str, objects: bool = False) -> tuple[float, float, float | None]:
        """An Area name (its centroid, no heading), 'x y yaw', or (``objects``) an Object's name (its
        centre: the standoff pose is placed when planning); ValueError naming the choices otherwise."""
        assert self.env is not None
        pose = parse_pose(text)
        if pose is not None:
            return pose
        name = text.strip()
        if name in self.model.areas:
            centre = self.model.areas[name].centroid
            return float(centre.x), float(centre.y), None
        if objects and name in self.model.objects:
            found = self.model.objects[name]
            return float(found.x), float(found.y), None
        areas = ", ".join(sorted(self.model.areas)) or "none"
        also = f", an Object of it ({', '.join(sorted(self.model.objects)) or 'none'})" if objects else ""
        raise ValueError(f"{self.owner}: {where} = {text!r} is neither an Area of environment "
                         f"{self.env.name!r} ({areas}){also} nor 'x y yaw' in the map frame")

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``goal`` Parameter (Table 7.1 "Goal"): navigate there from the next frame.

        Setting a goal again, even the same one, starts a new navigation (the robot may have moved);
        an empty goal cancels it (the base is told to stop).
        """
        if "goal" not in parameters:
            return
        text = parameters["goal"]
        if not isinstance(text, str):
            raise ValueError(f"{self.owner}: service parameter 'goal' = {text!r} must be an Area name or 'x y yaw'")
        if self.env is None:
            self.setup()
        cancelled = not text.strip()
        # only a goal still being worked on is cancelled; one that ended keeps its result
        running = self.goal is not None and self.phase in ("planning", "active")
        previous = self.goal_text if running else ""
        self.goal = None if cancelled else self._place(text, "service parameter 'goal'", objects=True)
        named = text.strip()
        self.goal_object = named if (named in self.model.objects and named not in self.model.areas
                                     and parse_pose(text) is None) else None
        self.object_placed = False
        self.routes.aim_at(self.goal_object)
        self._pending_goal = None
        self.plan, self.target = None, None
        if cancelled:  # the cancelled goal's result, as an action's CANCELED: a behavior following it ends
            self.goal_text, self.phase = previous, "cancelled" if running else "idle"
            self.reason = "cancelled: the goal was set empty" if running else ""
        else:
            self.goal_text, self.phase, self.reason = text, "planning", ""
        self.routes.reset()
        self.unlocalized_since, self.settling, self.at_goal, self.turning = None, False, False, False

    # ------------------------------------------------------------------ delegation

    def state(self) -> dict[str, Any]:
        """The goal, the plan and the filter (particles included), codec-able: a copy on another node
        (§3.1.2.5–6 delegation of the Navigation computation) goes on with the same results."""
        if self.localizer is None:
            return {}
        return {
            "kind": "amcl-navigation", "goal_text": self.goal_text,
            "goal_object": self.goal_object, "object_placed": self.object_placed,
            "goal": None if self.goal is None else list(self.goal), "pending": self._pending_goal,
            "phase": self.phase, "reason": self.reason,
            "plan": None if self.plan is None else [list(p) for p in self.plan], "segment": self.segment,
            "target": None if self.target is None else list(self.target),
            "path_id": self.path_id, "plan_length": self.plan_length,
            "obstacles": self.routes.areas(),
            "unlocalized_since": self.unlocalized_since, "stopped": self.stopped, "settling": self.settling,
            "at_goal": self.at_goal,  # (turning is made again by each frame's _navigate before it is used)
            "localizer": self.localizer.state(), "zoom": None if self.zoom is None else self.zoom.state(),
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Go on from :meth:`state` of another copy (after ``setup()``); ValueError naming what is wrong."""
        if not state:
            return
        if self.localizer is None:
            self.setup()
        assert self.localizer is not None and self.env is not None
        try:
            if state.get("kind") != "amcl-navigation":
                raise ValueError(f"kind is {state.get('kind')!r}")
            goal = state["goal"]
            self.goal = None if goal is None else (float(goal[0]), float(goal[1]), goal[2])
            self.goal_text, self._pending_goal = str(state["goal_text"]), state["pending"]
            self.goal_object, self.object_placed = state.get("goal_object"), bool(state.get("object_placed"))
            self.routes.aim_at(self.goal_object)
            self.phase, self.reason = str(state["phase"]), str(state["reason"])
            plan = state["plan"]
            self.plan = None if plan is None else [(float(x), float(y)) for x, y in plan]
            self.segment, self.path_id = int(state["segment"]), int(state["path_id"])
            target = state["target"]
            self.target = None if target is None else (float(target[0]), float(target[1]))
            self.plan_length = float(state["plan_length"])
            self.unlocalized_since, self.stopped = state["unlocalized_since"], bool(state["stopped"])
            self.settling = bool(state.get("settling", False))
            self.at_goal = bool(state.get("at_goal", False))
            self.routes.restore(state["obstacles"])
            self.localizer.restore(state["localizer"])
            if self.zoom is not None:
                self.zoom.restore(state.get("zoom"))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ValueError(f"{self.owner}: not an amcl-navigation state ({exc})") from None

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """One Navigation frame: localize, (re)plan, publish pose, status and path (module docstring)."""
        inputs = mapping(data, self.owner, "the input")
        unknown = sorted(set(map(str, inputs)) - set(INPUTS))
        if unknown:
            raise ValueError(f"{self.owner}: unknown inputs {unknown}; the service's Inputs must be named scan, odom")
        if self.localizer is None:
            self.setup()
        assert self.localizer is not None
        now = context.stamp
        scan = None if inputs.get("scan") is None else mapping(inputs["scan"], self.owner, "input 'scan'")
        odom_message = inputs.get("odom")
        result: dict[str, Any] = {}
        estimate = None
        if odom_message is not None:
            odom_fields = mapping(odom_message, self.owner, "input 'odom'")
            odom = pose_of(odom_fields, self.owner, "input 'odom'")
            twist = odom_fields.get("twist")
            speeds = [twist.get(k) for k in ("linear", "angular")] if isinstance(twist, Mapping) else []
            self.stopped = all(isinstance(v, int | float) and abs(v) < STOPPED for v in speeds)
            estimate = self.localizer.update(odom, scan)
        if estimate is not None:
            pose: Pose = (float(estimate.pose[0]), float(estimate.pose[1]), float(wrap(float(estimate.pose[2]))))
            result["pose"] = {"stamp": now, "pose": pose_message(pose),
                              "covariance": [float(v) for v in np.asarray(estimate.covariance).ravel()],
                              "dispersion": float(estimate.dispersion)}
            result["dispersion"] = float(estimate.dispersion)
            cloud = particle_cloud(self.localizer.filter, self.params["cloudSize"], now)
            if cloud is not None:
                result["particles"] = cloud
            if self.zoom is not None:
                result["zoom"] = self.zoom.update(pose[0], pose[1], now)
        if self.goal is None:
            if self.path_id:  # a cancelled goal: keep the base stopped
                result["path"] = {"id": self.path_id, "goal": "", "frame": "odom", "points": [], "yaw": None,
                                  "speed": float(self.params["speed"])}
            if self.phase == "cancelled" and self.goal_text:
                result["status"] = {"goal": self.goal_text, "state": "cancelled", "path_length": 0.0,
                                    "remaining": 0.0, "reason": self.reason}
            return result
        localized = estimate is not None and uncertainty(estimate) <= self.params["maxUncertainty"]
        if self.phase in ("planning", "active"):
            if not localized or estimate is None:
                self._unlocalized(now, self._why(estimate, odom_message is not None))
            else:
                self.unlocalized_since = None
                self._navigate(pose, scan, now)
        result["status"] = self._status(pose if localized else None)
        result["path"] = self._path()
        return result

    def _why(self, estimate: Estimate | None, odometry: bool) -> str:
        if estimate is not None:
            return f"uncertainty {uncertainty(estimate):.2f} m above {self.params['maxUncertainty']:g} m"
        return "no scan received" if odometry else "no odometry received"
