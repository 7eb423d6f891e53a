"""``plugin.flight-control``: a multirotor flown to goals by velocity set-points, the ``flight``
interface (docs/interfaces.md; PX4 offboard / MAVROS ``setpoint_velocity`` as a goal service).

Configured by its Params only — speeds, gains, tolerances; nothing of a particular airframe — and
its inputs (``{input name: newest value or None}``):

- ``goal`` (FlightGoal, :mod:`plugins.flight.goals`): takeoff, goto, land, hold, each by a fresh id;
- ``position``: a position fix (x, y, z on the map, z above the floor) or a pose message;
- optional ``heading`` (rad, a compass), ``velocity`` (optical flow over ground, heading frame, m/s)
  and ``altitude`` (a range finder's height above what lies under the robot, m) —
  :mod:`plugins.flight.estimate` reads each and blends them.

Outputs (only those naming a service Output are published):

- ``cmd_vel`` (geometry_msgs/Twist, every frame once a position is known): ``linear {x: ahead, y:
  left, z: up}`` in the heading frame and ``angular.z``, for the airframe's velocity loop (a
  ``controller.twist-axes`` splits it into one set point per actuator);
- ``status`` (FlightStatus) of the newest goal: ``{stamp, id, action, state: active | arrived |
  landed | failed, remaining (m), altitude (m), reason}``;
- ``pose`` (geometry_msgs/PoseStamped on the wire): ``{stamp, frame: map, pose: {x, y, z, yaw}}``;
- the measures ``active`` (0 after a failed goal) and ``remaining``.

Flying: a P law on the position error, the horizontal speed bounded by ``speed`` (the service
Parameter ``speed`` overrides it), the climb by ``climbRate``, the turn by ``maxYawRate``. Arrived:
within ``tolerance`` (m) and ``yawTolerance`` for ``settle`` s. Landing: descend at
``landingSpeed`` holding x, y; landed once the descent rate, fitted over ``landingWindow`` s, is
below a quarter of it (and the altitude input, when there is one, reads below ``landedAltitude``). Landed,
it keeps asking to descend, so the rotors idle. Failed: a bad goal (its ``reason``), a goto while
landed, no position fix for ``staleAfter`` s (the command is then zero velocity: the airframe holds
itself), or not arrived by the goal's deadline (twice its flying time plus ``timeoutMargin``).
A failed or arrived goal hovers where it ended.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.resources import Plugin
from plugins.environment.airspace import Airspace
from plugins.environment_file import environment_of
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ANY, ENVIRONMENT_FILE, MAPPING, P, Params, Ports

from .estimate import Estimator, Pose3, read_position, read_scalar, read_velocity
from .goals import Flight, accept, wrap

HOVER = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


def _twist(ahead: float, left: float, up: float, turn: float) -> dict[str, Any]:
    return {"linear": {"x": ahead, "y": left, "z": up}, "angular": {"x": 0.0, "y": 0.0, "z": turn}}


class FlightControl(ProcessingPlugin):
    """Flight goals to velocity set-points, and their status (see the module docstring)."""

    PORTS = Ports(inputs={"heading": ANY, "altitude": ANY, "velocity": ANY, "*": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "flight"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("speed", 1.0, "Top horizontal speed; the service Parameter 'speed' overrides it.", unit="m/s", above=0.0),
        P("climbRate", 0.5, "Top vertical speed, up or down.", unit="m/s", above=0.0),
        P("landingSpeed", 0.3, "Descent speed of a landing.", unit="m/s", above=0.0),
        P("maxYawRate", 1.0, "Top turn rate.", unit="rad/s", above=0.0),
        P("gain", 1.0, "Speed asked per metre of position error.", unit="1/s", above=0.0),
        P("yawGain", 1.5, "Turn rate asked per radian of heading error.", unit="1/s", above=0.0),
        P("tolerance", 0.2, "Distance to the target at which a goal is reached.", unit="m", above=0.0),
        P("yawTolerance", 0.15, "Heading error at which a goal is reached.", unit="rad", above=0.0),
        P("settle", 0.5, "How long a goal must stay reached to end.", unit="s", above=0.0),
        P("landingWindow", 1.0, "Span over which a landing's descent rate is measured (longer: less noise).",
          unit="s", above=0.0),
        P("landedAltitude", 0.3, "Highest altitude input reading of a landed robot (when there is one).",
          unit="m", above=0.0),
        P("fixGain", 1.0, "Share of the gap to each new position fix the estimate closes (1: the fix).",
          above=0.0, max=1.0),
        P("staleAfter", 1.0, "A goal fails after this long without a new position fix.", unit="s", above=0.0),
        P("timeoutMargin", 10.0, "Time a goal has beyond twice its flying time.", unit="s", min=0.0),
        P("environment", "", "File holding the system's <Environment>: each goto's and takeoff's legs are checked "
          "against its solids and their heights (empty: not checked).", type=str, file=ENVIRONMENT_FILE),
        P("radius", None, "The robot's horizontal radius, rotors included (required with 'environment').",
          type=float, unit="m", above=0.0),
        P("halfHeight", 0.15, "Half the robot's height, landing gear included (with 'environment').", unit="m",
          min=0.0),
        P("clearance", 0.3, "Margin kept around the robot's body from every solid (with 'environment').",
          unit="m", min=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        v = self.params
        self.speed: float = v["speed"]
        self.estimator = Estimator(v["fixGain"])
        self.flight: Flight | None = None
        self.landed: bool | None = None  # unknown until the first estimate
        self._message: Any = None
        self.airspace: Airspace | None = None
        if (problems := self.problems(record, None)):
            raise ParamError(f"{self.owner}: {problems[0][1]}")

    @classmethod
    def problems(cls, record: Plugin, system: System | None) -> list[tuple[Any, str]]:
        """An ``environment`` without the ``radius`` its checks need (verify reports it at the Param)."""
        given = {param.name: param for param in record.params}
        if "environment" in given and given["environment"].value and "radius" not in given:
            return [(given["environment"], "checking flights against 'environment' needs parameter 'radius' "
                                            "(the robot's horizontal radius, rotors included)")]
        return []

    def setup(self) -> None:
        """Read the environment whose solids the flights are checked against (when one is named)."""
        if self.params["environment"]:
            self.airspace = Airspace(environment_of(config_dir(self.record) / self.params["environment"], self.owner))

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``speed`` Parameter caps the horizontal speed."""
        if "speed" in parameters:
            value = parameters["speed"]
            if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
                raise ValueError(f"{self.owner}: service parameter 'speed' = {value!r} must be a speed > 0 m/s")
            self.speed = float(value)

    # ------------------------------------------------------------------ frames

    def _inputs(self, data: Mapping[str, Any]) -> tuple[Any, float | None, tuple[float, float] | None, float | None]:
        owner = self.owner
        fix = None if data.get("position") is None else read_position(data["position"], owner)
        heading = None if data.get("heading") is None else read_scalar(data["heading"], owner, "heading",
                                                                          ("yaw", "data", "heading"))
        velocity = None if data.get("velocity") is None else read_velocity(data["velocity"], owner)
        altitude = None if data.get("altitude") is None else read_scalar(data["altitude"], owner, "altitude",
                                                                           ("range", "data", "altitude"))
        return fix, heading, velocity, altitude

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The velocity command, the newest goal's status, the pose estimate and the measures.

        Raises:
            ValueError: ``data`` is not a mapping of the inputs, or an input has no readable value.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'goal': …, 'position': …}}, got {type(data).__name__}")
        now = context.stamp
        fix, heading, velocity, altitude = self._inputs(data)
        pose = self.estimator.update(now, fix, heading, velocity)
        if pose is not None and self.landed is None:
            self.landed = (altitude if altitude is not None else pose.z) <= self.params["landedAltitude"]
        message = data.get("goal")
        if message is not None and message != self._message:
            self._message = message
            self.flight = self._start(accept(message, pose, bool(self.landed)), pose, now)
        result: dict[str, Any] = {}
        if pose is None:
            return result
        result["cmd_vel"] = self._command(pose, altitude, now)
        result["pose"] = {"stamp": now, "frame": "map",
                          "pose": {"x": round(pose.x, 4), "y": round(pose.y, 4), "z": round(pose.z, 4),
                                   "yaw": round(pose.yaw, 4)}}
        flight = self.flight
        remaining = 0.0
        if flight is not None and flight.target is not None:
            points = [pose, *flight.legs, flight.target]
            remaining = sum(a.distance(b) for a, b in itertools.pairwise(points))
        result["active"] = 0 if flight is not None and flight.state == "failed" else 1
        result["remaining"] = round(remaining, 3)
        if flight is not None:
            result["status"] = {"stamp": now, "id": flight.id, "action": flight.action, "state": flight.state,
                                "remaining": round(remaining, 3),
                                "altitude": round(altitude if altitude is not None else pose.z, 3),
                                "reason": flight.reason}
        return result

    def _blocked(self, flight: Flight, pose: Pose3) -> str:
        """What the goal's legs meet in the environment, in words ("" when they are clear)."""
        if self.airspace is None or flight.action not in ("goto", "takeoff") or flight.target is None:
            return ""
        v = self.params
        points = [pose, *flight.legs, flight.target]
        for number, (a, b) in enumerate(itertools.pairwise(points), start=1):
            met = self.airspace.path_blockers((a.x, a.y, a.z), (b.x, b.y, b.z), radius=v["radius"] + v["clearance"],
                                              half_height=v["halfHeight"] + v["clearance"])
            met = [m for m in met if m != "floor" or number > 1 or b.z < a.z]  # leaving the ground is no collision
            if met:
                return (f"the flight's leg {number} from ({a.x:.2f}, {a.y:.2f}, {a.z:.2f}) to ({b.x:.2f}, "
                        f"{b.y:.2f}, {b.z:.2f}) meets {', '.join(repr(m) for m in met)}")
        return ""

    def _start(self, flight: Flight, pose: Pose3 | None, now: float) -> Flight:
        """Time a new goal: its deadline from the flying it asks."""
        flight.started = now
        if flight.state == "failed" or flight.target is None or pose is None:
            return flight
        blocked = self._blocked(flight, pose)
        if blocked:
            flight.fail(f"goal {flight.id}: {blocked}")
            flight.target, flight.legs = Pose3(pose.x, pose.y, pose.z, pose.yaw), []
            return flight
        target, margin = flight.target, self.params["timeoutMargin"]
        points = [pose, *flight.legs, target]
        horizontal = sum(math.hypot(b.x - a.x, b.y - a.y) for a, b in itertools.pairwise(points))
        vertical = sum(abs(b.z - a.z) for a, b in itertools.pairwise(points))
        flying = horizontal / self.speed + vertical / self.params["climbRate"]
        if flight.action == "land":
            flying = max(pose.z, 0.5) / self.params["landingSpeed"]
        flight.deadline = math.inf if flight.action == "hold" else now + 2.0 * flying + margin
        if flight.action == "takeoff":
            self.landed = False
        return flight

    def _command(self, pose: Pose3, altitude: float | None, now: float) -> dict[str, Any]:
        """The velocity set-point for this frame (module docstring)."""
        flight = self.flight
        v = self.params
        if now - self.estimator.last_fix > v["staleAfter"]:
            if flight is not None and flight.state == "active":
                flight.fail(f"no position fix for {v['staleAfter']:g} s")
                flight.target = pose
            return dict(HOVER)
        if flight is None or flight.target is None:
            return _twist(0.0, 0.0, -v["landingSpeed"], 0.0) if self.landed else dict(HOVER)
        if flight.state == "landed":
            return _twist(0.0, 0.0, -v["landingSpeed"], 0.0)
        if flight.state == "active" and now > flight.deadline:
            flight.fail(f"not {'landed' if flight.action == 'land' else 'reached'} by its deadline "
                        f"({flight.deadline - (flight.started or now):.1f} s)")
            flight.target = Pose3(pose.x, pose.y, pose.z, pose.yaw)
        if flight.state == "failed" and flight.target is None:
            return dict(HOVER)
        if flight.legs and pose.distance(flight.legs[0]) <= v["tolerance"]:
            flight.legs.pop(0)
        target = flight.legs[0] if flight.legs else flight.target
        assert target is not None
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        ex, ey = target.x - pose.x, target.y - pose.y
        vx, vy = v["gain"] * ex, v["gain"] * ey
        horizontal = math.hypot(vx, vy)
        if horizontal > self.speed:
            vx, vy = vx * self.speed / horizontal, vy * self.speed / horizontal
        turn_error = wrap(target.yaw - pose.yaw)
        turn = max(-v["maxYawRate"], min(v["maxYawRate"], v["yawGain"] * turn_error))
        if flight.action == "land" and flight.state == "active":
            up = -v["landingSpeed"]
            self._judge_landing(flight, pose, altitude, now)
        else:
            up = max(-v["climbRate"], min(v["climbRate"], v["gain"] * (target.z - pose.z)))
            if flight.state == "active" and not flight.legs:
                reached = pose.distance(target) <= v["tolerance"] and abs(turn_error) <= v["yawTolerance"]
                if not reached:
                    flight.settled_since = None
                elif flight.settled_since is None:
                    flight.settled_since = now
                if flight.settled_since is not None and now - flight.settled_since >= v["settle"]:
                    flight.state = "arrived"
        return _twist(c * vx + s * vy, -s * vx + c * vy, up, turn)

    def _judge_landing(self, flight: Flight, pose: Pose3, altitude: float | None, now: float) -> None:
        """Landed once the fitted descent rate is below a quarter of ``landingSpeed`` (and the altitude reads low)."""
        v = self.params
        window = v["landingWindow"]
        flight.heights.append((now, pose.z))
        while flight.heights and flight.heights[0][0] < now - window:
            flight.heights.pop(0)
        times = [t for t, _ in flight.heights]
        if len(times) < 3 or times[-1] - times[0] < 0.8 * window:
            return
        mean_t, mean_z = sum(times) / len(times), sum(z for _, z in flight.heights) / len(times)
        spread = sum((t - mean_t) ** 2 for t in times)
        rate = sum((t - mean_t) * (z - mean_z) for t, z in flight.heights) / spread if spread > 0 else 0.0
        if rate > -0.25 * v["landingSpeed"] and (altitude is None or altitude <= v["landedAltitude"]):
            flight.state, self.landed = "landed", True

    def state(self) -> dict[str, Any]:
        """What a delegation carries: the speed and whether the robot has landed (a goal is resent)."""
        return {"kind": "flight-control", "speed": self.speed, "landed": self.landed}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a flight-control plugin."""
        if state.get("kind") != "flight-control":
            raise ValueError(f"{self.owner}: not a flight-control state: {state!r}"[:200])
        self.speed = float(state.get("speed", self.speed))
        landed = state.get("landed")
        self.landed = None if landed is None else bool(landed)
