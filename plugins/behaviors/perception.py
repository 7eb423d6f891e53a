"""Perception behaviors over the ``fusion``, ``object-detection`` and ``pan-tilt-tracking`` interfaces.

``spot-objects`` waits until the fused recognition holds the target and writes its position;
``track-object`` waits until a camera head follows it; ``fix-object`` holds it until the recognition
has been reliable long enough and writes its position (a plan signal's payload or a topic). Targets
are chosen by shape or name and texture (Params ``target``, ``targetTexture``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from runtime.missions.behaviors import Behavior, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .messages import TARGET_PARAMS, find_target, object_position


class SpotObjects(Behavior):
    """SPOT, SPOT_COOP: waits until the fused recognition holds the target (untraceable), then
    writes its position (an ``ObjectPosition``) on the ``target`` output."""

    USES = Uses(Use("fusion", "fusion", "the recognition looked in, unless an input named objects gives it",
                    optional=True))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        *TARGET_PARAMS, P("minSources", 1, "Fewest recognition sources that must have seen the object.")
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    def step(self) -> BehaviorStatus:
        """Done when the fused recognition holds the target; its position is then written on ``target``."""
        result = self.read("objects") if "objects" in self.context.inputs else self.service("fusion").output("objects")
        p = self.params
        found = find_target(result, p["target"], p["targetTexture"], p["minSources"])
        if found is None:
            return BehaviorStatus(progress=0.0)
        self.write("target", object_position(found, self.context.now()))  # an ObjectPosition (topic or signal)
        return BehaviorStatus(progress=1.0, done=True, detail=f"{found.get('name')} at {found.get('reliability')}")


class TrackObject(Behavior):
    """OBJ_TRACK: waits until the pan-tilt recognition sees the target and the head follows it."""

    USES = Uses(Use("recog", "object-detection", "sees the target"),
                Use("track", "pan-tilt-tracking", "keeps the head on it (measure moving)"))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(*TARGET_PARAMS)

    def step(self) -> BehaviorStatus:
        """Done once the pan-tilt recognition sees the target and the head is following it."""
        found = find_target(
            self.service("recog").output("objects"), self.params["target"], self.params["targetTexture"]
        )
        moving = self.service("track").measures().get("moving")
        if found is not None and moving:
            return BehaviorStatus(progress=1.0, done=True)
        return BehaviorStatus(progress=0.5 if found is not None else 0.0)


class FixObject(Behavior):
    """OBJ_FIX: holds the camera on the target until the recognition has been reliable for
    ``holdTime`` seconds, then writes the target's position (an ``ObjectPosition``) on its
    outputs: the payload of the plan signal (``<Output signal=…>``) or a topic. With a ``track``
    service the position is the tracked target it places on the map; else the recognition's."""

    USES = Uses(Use("recog", "object-detection", "sees the target and rates it"),
                Use("track", "pan-tilt-tracking", "places the target on the map", optional=True))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("holdTime", 2.0, "How long the recognition must stay reliable.", unit="s"),
        *TARGET_PARAMS,
        P("minReliability", 0.7, "Reliability the recognition must keep."),
    )
    PORTS = Ports(outputs={"*": MAPPING})

    def start(self) -> None:
        """Forget the previous holding time."""
        super().start()
        self.since: float | None = None

    def step(self) -> BehaviorStatus:
        """Done once the recognition kept ``minReliability`` for ``holdTime`` s; the position goes on the outputs."""
        p = self.params
        found = find_target(self.service("recog").output("objects"), p["target"], p["targetTexture"])
        now = self.context.now()
        if found is None or float(found.get("reliability", 0.0)) < p["minReliability"]:
            self.since = None
            return BehaviorStatus(progress=0.0)
        self.since = now if self.since is None else self.since
        held = now - self.since
        if held >= p["holdTime"]:
            position = object_position(found, now)
            if "track" in self.context.services:
                target = self.service("track").output("target")
                if not isinstance(target, Mapping) or target.get("frame") != "map":
                    return BehaviorStatus(progress=0.99, detail="waiting for the tracked target's map position")
                position = object_position({**target, "name": target.get("label", found.get("name"))}, now)
            for port in self.record.outputs:
                self.write(port.name, position)
            return BehaviorStatus(progress=1.0, done=True)
        return BehaviorStatus(progress=held / p["holdTime"])
