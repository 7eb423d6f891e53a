"""Service interfaces: what a behavior may rely on a service to offer (issue M, Nav2's plugin interfaces).

A behavior reads a service's outputs and configures its parameters by name; an interface names
them once, for every kind that implements it. Two declarations meet here, both checked by
``verify`` before anything is built:

- a processing plugin kind that is the output (leaf) plugin of a service's profiles declares the
  interface it implements, ``PROVIDES = "navigation"``; a ``<Service interface="…">`` says it too
  (and must agree with its kinds; a service on a ROS kernel has no kind to say it);
- a behavior kind declares the services it needs under the aliases it uses, as BehaviorTree.CPP's
  ``providedPorts``: ``USES = Uses(Use("nav", "navigation", "…"))``. Each ``<Uses as=…>`` of a
  ``<Behavior>`` is checked against it: a required alias missing, an alias bound to a service of
  another interface, or to a service whose interface is not known, is refused at its ``FILE:LINE:COL``.
  Further ``<Uses>`` (services the behavior only configures or requires a quality of, for eq. 5.1)
  are accepted.

A service of an interface must have the interface's Inputs, Outputs and Parameters (by name). The
catalogue :data:`STANDARD` is what ``ckm-plugins interfaces`` and ``docs/interfaces.md`` show.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ckmconf.model import Service, SmartResource

    from ..registry import Registry


@dataclass(frozen=True)
class Port:
    """One Input, Output, Parameter or quality measure an interface requires, and what it carries.

    ``messages`` names the ROS 2 types its topic may carry as they are (the first a standard one
    where ROS 2 has one, else a ``ckm_interfaces`` type CKM ships; D276), ``fields`` the fields every
    kind of the interface writes (``pose.x`` a nested field, ``objects[].name`` one of a list's
    elements); a kind that writes more declares them itself (:func:`writes_of`).
    """

    name: str
    doc: str
    messages: tuple[str, ...] = ()
    fields: tuple[str, ...] = ()


@dataclass(frozen=True)
class Interface:
    """A named service interface: the ports a service of it has, and how its goals behave.

    ``goals`` describes the goal protocol of a long-running service (empty for a streaming one).
    """

    name: str
    summary: str
    inputs: tuple[Port, ...] = ()
    outputs: tuple[Port, ...] = ()
    parameters: tuple[Port, ...] = ()
    measures: tuple[Port, ...] = ()
    goals: str = ""

    def port(self, output: str, outputs: int) -> Port | None:
        """The Output port a service Output of this name is (with one Output and one port, that one)."""
        found = next((p for p in self.outputs if p.name == output), None)
        return found if found is not None or outputs != 1 or len(self.outputs) != 1 else self.outputs[0]

    def missing(self, inputs: set[str], outputs: set[str], parameters: set[str], measures: set[str]) -> list[str]:
        """What a service with these port and measure names lacks to be of this interface, in words."""
        lacking = []
        for label, required, present in (("Input", self.inputs, inputs), ("Output", self.outputs, outputs),
                                         ("Parameter", self.parameters, parameters),
                                         ("QualityMeasure", self.measures, measures)):
            lacking += [f"{label} {port.name!r}" for port in required if port.name not in present]
        return lacking


_ID_GOALS = (
    "Each goal carries a fresh `id` and the status names the `id` of the goal it reports, so a status "
    "left over from an earlier goal is never read as this one's; a newer goal preempts the older one."
)

_SCAN = ("stamp", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min",
         "range_max", "ranges", "intensities")
_STATUS = ("stamp", "id", "group", "pose", "state", "active", "error", "holding", "contact", "opening")
_ESTIMATE = ("stamp", "pose.x", "pose.y", "pose.yaw", "covariance", "dispersion")
LASER_SCAN, ODOMETRY = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_STAMPED, TWIST = "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/Twist"
CKM = "ckm_interfaces/msg/"
"""The package of the message types CKM ships (ckmconf/ros/ckm_interfaces, D278)."""

STANDARD: dict[str, Interface] = {
    i.name: i
    for i in (
        Interface(
            "laser-scan",
            "A planar range scanner's scans, in the frame of its mount.",
            outputs=(Port("scan", "sensor_msgs/LaserScan's fields: `stamp` (its `header.stamp` on the ROS type), "
                                  "`angle_min`, `angle_max`, `angle_increment` (rad), `time_increment`, "
                                  "`scan_time` (s), `range_min`, `range_max` (m), `ranges` (m, one per beam; "
                                  "REP 117's inf, -inf, nan), `intensities`", (LASER_SCAN,), _SCAN),),
        ),
        Interface(
            "base-drive",
            "A mobile base driven by relative moves, with wheel odometry.",
            inputs=(Port("move_goal", "a move `{id, frame: robot, x, y (m), yaw (rad)}` from where the base "
                                      "stands; the behaviors' `move` Output is this topic", (f"{CKM}MoveGoal",),
                         ("id", "frame", "x", "y", "yaw")),),
            outputs=(
                Port("move_status", "`{id, state: moving | done | failed, remaining, total (m), reason}` of the "
                                    "newest move; `reason` says why it failed (preempted, no odometry, its "
                                    "deadline passed)", (f"{CKM}MoveStatus",),
                     ("id", "state", "remaining", "total", "reason")),
                Port("odom", "`{stamp, pose: {x, y, yaw}, twist: {linear, angular}, dispersion}` (m, rad, m/s, "
                             "rad/s; dispersion in m); as nav_msgs/Odometry the pose's covariance holds the "
                             "dispersion d (σx² = σy² = d²/2)", (ODOMETRY,),
                     ("stamp", "pose.x", "pose.y", "pose.yaw", "twist.linear", "twist.angular", "dispersion")),
            ),
            parameters=(Port("speed", "the top linear speed of a move (m/s)"),),
            goals=_ID_GOALS,
        ),
        Interface(
            "navigation",
            "Localization on the system's map and path planning to a goal pose.",
            outputs=(
                Port("pose", "the estimate `{stamp, pose: {x, y, yaw}, covariance (3x3, row-major), dispersion}` "
                             "on the map (m, rad); geometry_msgs/PoseWithCovarianceStamped carries all but the "
                             "`dispersion` (the service's own quality measure), ckm_interfaces/PoseEstimate all",
                     (POSE, f"{CKM}PoseEstimate"), _ESTIMATE),
                Port("status", "`{goal, state: planning | active | arrived | failed | cancelled, path_length, "
                               "remaining (m), reason}` of the newest goal; `reason` says why it failed or "
                               "was cancelled",
                     (f"{CKM}NavigationStatus",), ("goal", "state", "path_length", "remaining", "reason")),
            ),
            parameters=(Port("goal", "the goal on the map: `\"x y yaw\"` (m, m, rad), an Area's name, or an "
                                     "Object's name (the pose short of it, facing it); empty: none (the base "
                                     "stands). A Parameter, not a topic: no message type"),),
            goals="The status echoes the goal it reports (`goal`), so a status of an earlier goal is never read as "
                  "this one's; setting a goal preempts the older one, an empty goal cancels it (a goal still "
                  "planned or driven to then reports `cancelled`, as an action's result; one that ended keeps "
                  "its result).",
        ),
        Interface(
            "arm-motion",
            "An arm (and its gripper) moved to named poses or to Cartesian targets.",
            inputs=(Port("goal", "a goal `{id, group: arm | gripper, pose}`, or an arm goal `{id, group: arm, "
                                 "target: {x, y, z (m, base frame), pitch (rad from the vertical; optional on "
                                 "an arm that cannot set it)}}`; the behaviors' `arm_goal` Output is this "
                                 "topic", (f"{CKM}ArmGoal",), ("id", "group", "pose")),),
            outputs=(Port("status", "`{stamp, id, group, pose, state: moving | reached | failed, active, error, "
                                    "holding, contact, opening}` of the newest goal, and `target` for a target "
                                    "goal: `error` why it "
                                    "failed (unreachable, beyond a joint limit, a pitch the arm cannot set), "
                                    "`holding` a gripper goal that closed on an object, `contact` an arm goal "
                                    "stopped by one, `opening` the gripper's share of its range",
                          (f"{CKM}ArmStatus",), _STATUS),),
            goals=_ID_GOALS,
        ),
        Interface(
            "gripper",
            "A gripper opened, closed or set to an opening, reporting whether it holds an object "
            "(control_msgs/GripperCommand as an action).",
            inputs=(Port("command", "a command `{id, action: open | close | position, position (a share 0..1 of "
                                    "the range, or m), max_effort (N)}`; the behaviors' `gripper_command` "
                                    "Output is this topic", (f"{CKM}GripperCommand",),
                         ("id", "action", "position", "max_effort")),),
            outputs=(Port("status", "`{stamp, id, action, state: moving | reached | holding | stalled | failed, "
                                    "position, opening, holding, effort, max_effort, reason}` of the newest "
                                    "command: `holding` the fingers closed on an object (stopped short of "
                                    "their target), `stalled` stopped short while opening, `reason` why it "
                                    "failed or stalled", (f"{CKM}GripperStatus",),
                          ("stamp", "id", "action", "state", "position", "opening", "holding", "effort",
                           "max_effort", "reason")),),
            measures=(Port("holding", "1 while the newest command holds an object, else 0"),),
            goals=_ID_GOALS,
        ),
        Interface(
            "object-detection",
            "Objects recognised in a sensor's frames (texture, depth shape or colour).",
            outputs=(Port("objects", "`{objects: [{name, x, y, …, reliability}], reliability}` in the sensor's "
                                     "frame; each kind's further fields below", (f"{CKM}Detections",),
                          ("objects[].name", "objects[].x", "objects[].y", "objects[].reliability", "reliability")),),
        ),
        Interface(
            "fusion",
            "Recognitions of several sensors fused into one set of objects on the map.",
            outputs=(Port("objects", "`{objects: [{name, shape, texture, frame, x, y, z, reliability, "
                                     "sources, …}], reliability}`", (f"{CKM}Detections",),
                          ("objects[].name", "objects[].shape", "objects[].texture", "objects[].frame",
                           "objects[].x", "objects[].y", "objects[].z", "objects[].reliability", "objects[].sources",
                           "reliability")),),
        ),
        Interface(
            "pan-tilt-tracking",
            "A camera head kept on a recognised object, placing it on the map.",
            outputs=(Port("target", "the tracked object `{stamp, label, frame, x, y, z, reliability}`",
                          (f"{CKM}ObjectPosition",), ("stamp", "label", "frame", "x", "y", "z", "reliability")),),
            measures=(Port("moving", "1 while the head follows the target"),),
        ),
        Interface(
            "localization",
            "A pose estimate on the system's map from odometry and range readings.",
            outputs=(Port("pose", "the pose estimate `{x, y, yaw, covariance (3x3, row-major), dispersion}` (m, "
                                  "rad); geometry_msgs/PoseWithCovarianceStamped carries all but the `dispersion` "
                                  "(the service's own quality measure)", (POSE,),
                          ("x", "y", "yaw", "covariance", "dispersion")),),
        ),
        Interface(
            "docking",
            "A base docked at a known dock (a charger, a station) and undocked from it.",
            inputs=(
                Port("goal", "a goal `{id, action: dock | undock, dock: a dock's name, or empty with its docked "
                             "pose x, y, yaw on the map}`; the behaviors' `dock_goal` Output is this topic",
                     (f"{CKM}DockGoal",), ("id", "action", "dock", "x", "y", "yaw")),
                Port("pose", "the base's pose estimate on the map (a navigation or localization `pose`)",
                     (POSE, f"{CKM}PoseEstimate", POSE_STAMPED), ("pose.x", "pose.y", "pose.yaw")),
                Port("move_status", "the base-drive service's `move_status`, for the moves the docking service "
                                    "sends on its `move_goal` Output", (f"{CKM}MoveStatus",),
                     ("id", "state", "reason")),
            ),
            outputs=(
                Port("move_goal", "relative moves `{id, frame: robot, x, y, yaw}` for the base-drive service's "
                                  "`move_goal` Input", (f"{CKM}MoveGoal",), ("id", "frame", "x", "y", "yaw")),
                Port("status", "`{stamp, id, action, state: staging | docking | docked | undocking | undocked | "
                               "failed, attempt, reason}` of the newest goal; `reason` says why an approach "
                               "failed (a move, no contact, too far off the dock)",
                     (f"{CKM}DockStatus",), ("stamp", "id", "action", "state", "attempt", "reason")),
            ),
            goals=_ID_GOALS,
        ),
        Interface(
            "flight",
            "A multirotor flown to goals (take off, go to, land, hold) by velocity set-points.",
            inputs=(
                Port("goal", "a goal `{id, action: takeoff | goto | land | hold, frame: map | robot, x, y, z (m), "
                             "yaw (rad; NaN keeps the heading)}`: a takeoff climbs `z` above where it stands, a "
                             "goto flies to (x, y, z) (z above the floor on the map), a land descends where it "
                             "is until it rests; the behaviors' `flight_goal` Output is this topic",
                     (f"{CKM}FlightGoal",), ("id", "action", "frame", "x", "y", "z", "yaw")),
                Port("position", "a position fix `{x, y, z}` on the map (UWB, motion capture, the simulator's "
                                 "`position` sensor; a PointStamped) or a pose message (PoseStamped, Odometry)",
                     ("geometry_msgs/msg/PointStamped", POSE_STAMPED, ODOMETRY), ("x", "y", "z")),
            ),
            outputs=(
                Port("cmd_vel", "the velocity set-point `{linear: {x: ahead, y: left, z: up}, angular: {z}}` in "
                                "the heading frame (m/s, rad/s), for the airframe's velocity loop",
                     (TWIST,), ("linear.x", "linear.y", "linear.z", "angular.z")),
                Port("status", "`{stamp, id, action, state: active | arrived | landed | failed, remaining (m), "
                               "altitude (m), reason}` of the newest goal; `reason` says why it failed (a bad "
                               "goal, a goto while landed, no position fix, its deadline passed)",
                     (f"{CKM}FlightStatus",), ("stamp", "id", "action", "state", "remaining", "altitude", "reason")),
                Port("pose", "the estimate `{stamp, frame: map, pose: {x, y, z, yaw}}` (m, rad)",
                     (POSE_STAMPED,), ("stamp", "frame", "pose.x", "pose.y", "pose.z", "pose.yaw")),
            ),
            parameters=(Port("speed", "the top horizontal speed (m/s)"),),
            goals=_ID_GOALS,
        ),
        Interface(
            "map-sharing",
            "The environment map's objects, updated from perception and shared between robots.",
            outputs=(Port("objects", "`{type: objects, map, stamp, objects: [...]}` updates of the map (a "
                                     "MessageType of the system or `bytes`: no ROS type holds a map object)",
                          (), ("type", "map", "stamp", "objects")),),
        ),
    )
}
"""The standard interfaces, by name."""


@dataclass(frozen=True)
class Use:
    """One service a behavior kind needs: the ``<Uses as>`` alias it reads it by, and its interface."""

    alias: str
    interface: str
    doc: str = ""
    optional: bool = False

    def __post_init__(self) -> None:
        if self.interface not in STANDARD:
            raise TypeError(f"use {self.alias!r}: no interface {self.interface!r} (known: {', '.join(STANDARD)})")


@dataclass(frozen=True)
class Uses:
    """The services a behavior kind declares (``USES``), in declaration order."""

    uses: tuple[Use, ...] = field(default=())

    def __init__(self, *uses: Use) -> None:
        aliases = [u.alias for u in uses]
        if len(set(aliases)) != len(aliases):
            raise TypeError(f"an alias is declared twice in {aliases}")
        object.__setattr__(self, "uses", uses)

    def __iter__(self) -> Iterator[Use]:
        return iter(self.uses)

    def by_alias(self) -> Mapping[str, Use]:
        """The declared uses by alias."""
        return {u.alias: u for u in self.uses}


def uses_of(cls: type[Any] | None) -> Uses | None:
    """The services a behavior kind declares (None: it declares none, so its ``<Uses>`` are not checked)."""
    declared = getattr(cls, "USES", None)
    return declared if isinstance(declared, Uses) else None


def writes_of(cls: type[Any] | None) -> Mapping[str, tuple[str, ...]]:
    """The fields a kind declares it writes (``WRITES``: Output name → field paths, as :class:`Port`'s
    ``fields``); empty when it declares none (its interface's ports then say what it writes)."""
    declared = getattr(cls, "WRITES", None) if cls is not None else None
    return declared if isinstance(declared, Mapping) else {}


def provided_by(cls: type[Any] | None) -> str | None:
    """The interface a processing plugin kind implements as a service's output plugin (None: none declared)."""
    provided = getattr(cls, "PROVIDES", None) if cls is not None else None
    return provided if isinstance(provided, str) and provided in STANDARD else None


def service_interface(resource: SmartResource, service: Service, registry: Registry) -> str | None:
    """The interface ``service`` of ``resource`` offers, resolved as ``verify`` does without its checks:
    its ``interface=``, else the one interface its scenarios' profiles' output plugin kinds ``PROVIDES``
    (looked up in ``registry``). None: an unknown name, no kind saying one, or kinds saying several.

    Raises:
        RegistryError: a plugin kind's entry point cannot be imported.
    """
    if service.interface is not None:
        return service.interface if service.interface in STANDARD else None
    plugins = {p.name: p.kind for p in resource.plugins} if resource.kernel != "ros" else {}
    profiles = {p.name: p for p in resource.profiles}
    provided = set()
    for scenario in service.scenarios:
        profile = profiles.get(scenario.profile)
        kind = plugins.get(profile.output_plugin()) if profile is not None else None
        name = provided_by(registry.find("plugin", kind)) if kind is not None else None
        if name is not None:
            provided.add(name)
    return provided.pop() if len(provided) == 1 else None


__all__ = ["CKM", "STANDARD", "Interface", "Port", "Use", "Uses", "provided_by", "service_interface", "uses_of",
           "writes_of"]
