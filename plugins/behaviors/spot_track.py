"""``behavior.spot`` and ``behavior.track``: the general perception states (D270).

The lab's ``spot-objects``, ``track-object`` and ``fix-object`` (:mod:`plugins.behaviors.perception`)
choose the target by the lab recognisers' shape and texture substrings, write on an output that
must be called ``target`` and need both a recognition and a head; they stay for the lab's missions.
These choose the object by its label (:mod:`plugins.behaviors.sightings`) and write on every output:

- ``spot``: done once an ``object-detection`` (``as="detection"``) or ``fusion`` (``as="fusion"``)
  service has shown the object with at least ``minReliability`` for ``holdTime`` seconds in a row
  (0: at the first sighting); its position is written as an ``ObjectPosition``: on the map when the
  fusion placed it or a ``navigation`` service (``as="nav"``, optional) gives the robot's pose, else
  in the frame the detector gave.
- ``track``: done once a ``pan-tilt-tracking`` service (``as="track"``) has followed a target
  answering to ``label`` with at least ``minReliability`` for ``holdTime`` seconds (its ``moving``
  measure at 1 throughout, unless ``needMoving`` is false); the tracked target is written.

Progress is the share of ``holdTime`` held (1 at the sighting when it is 0); the performance
(eq. 5.1) is that of the services used.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .messages import robot_pose
from .sightings import (
    SIGHTING_PARAMS,
    SIGHTING_USES,
    best_sighting,
    labels,
    map_sighting,
    mount_of,
    on_map,
    perception,
    sighting_problems,
)

_HOLD = P("holdTime", 0.0, "How long the object must stay seen, without a gap (0: the first sighting).",
          unit="s", min=0.0)


class _Held(Behavior):
    """Done once a sighting has held ``holdTime`` seconds in a row; writes it on every output."""

    def start(self) -> None:
        """Forget an earlier sighting."""
        super().start()
        self.since: float | None = None

    def _sighting(self) -> dict[str, Any] | None:
        raise NotImplementedError

    def step(self) -> BehaviorStatus:
        """Progress is the share of ``holdTime`` held; done (the sighting written) once it has all held."""
        found, now = self._sighting(), self.context.now()
        if found is None:
            self.since = None
            return BehaviorStatus(progress=0.0, detail=f"looking for {self.params['label'] or 'an object'}")
        self.since = now if self.since is None else self.since
        hold = self.params["holdTime"]
        held = now - self.since
        if held < hold:
            return BehaviorStatus(progress=held / hold, detail=f"{found['label']} seen for {held:.1f} s")
        for port in self.record.outputs:
            self.write(port.name, found)
        self.context.log("object seen", label=found["label"], frame=found["frame"], x=found["x"], y=found["y"],
                         reliability=found["reliability"])
        return BehaviorStatus(progress=1.0, done=True, detail=f"{found['label']} at {found['reliability']:.2f}")


class Spot(_Held):
    """``behavior.spot``: the object seen by the detection or the fusion (module docstring)."""

    USES = Uses(*SIGHTING_USES, Use("nav", "navigation", "its pose places a sighting on the map", optional=True))
    PARAMS: ClassVar[Mapping[str, Any]] = Params(*SIGHTING_PARAMS, _HOLD)
    PORTS = Ports(outputs={"*": MAPPING})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """One perception service watched."""
        return sighting_problems(record, system)

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.mount = mount_of(self.params["sensorPose"], self.owner)

    def _sighting(self) -> dict[str, Any] | None:
        item = best_sighting(perception(self), self.params["label"], self.params["minReliability"])
        if item is None:
            return None
        robot = robot_pose(self.service("nav").output("pose")) if "nav" in self.context.services else None
        where = on_map(item, robot, self.mount)
        if where is not None:
            return map_sighting(item, where, robot, self.context.now())
        if "nav" in self.context.services:
            return None  # the robot's pose first
        placed = map_sighting(item, (float(item.get("x") or 0.0), float(item.get("y") or 0.0),
                                     float(item.get("z") or 0.0)), None, self.context.now())
        return {**placed, "frame": str(item.get("frame") or "sensor")}  # where the detector saw it


class Track(_Held):
    """``behavior.track``: the pan-tilt head following the object (module docstring)."""

    USES = Uses(Use("track", "pan-tilt-tracking", "follows the target (measure moving) and places it"))
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("label", "", "The target's label (empty: whatever the head follows)."),
        P("minReliability", 0.5, "Least reliability the tracked target must keep.", min=0.0, max=1.0),
        _HOLD,
        P("needMoving", True, "Count only while the head follows the target (its 'moving' measure is 1)."),
    )
    PORTS = Ports(outputs={"*": MAPPING})

    def _sighting(self) -> dict[str, Any] | None:
        handle = self.service("track")
        target = handle.output("target")
        if not isinstance(target, Mapping) or (self.params["label"] and self.params["label"] not in labels(target)):
            return None
        reliability = target.get("reliability")
        if not isinstance(reliability, int | float) or reliability < self.params["minReliability"]:
            return None
        if self.params["needMoving"] and handle.measures().get("moving") != 1:
            return None
        where = (float(target.get("x") or 0.0), float(target.get("y") or 0.0), float(target.get("z") or 0.0))
        placed = map_sighting(target, where, None, self.context.now())
        return {**placed, "frame": str(target.get("frame") or "map")}
