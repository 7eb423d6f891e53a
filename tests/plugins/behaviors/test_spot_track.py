"""``behavior.spot`` and ``behavior.track`` (issue M, point 3; D270): the object chosen by its label and
reliability, held ``holdTime`` seconds, written on every output (on the map when it can be placed);
``spot`` in the closed loop on the Turtlebot and the rover, ``track`` over the real pan-tilt-track kind
on the Nao's head and on the station arm's turret, as are the lab's ``track-object`` and ``fix-object``."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorOutput, Uses
from plugins.behaviors.perception import FixObject, TrackObject
from plugins.behaviors.spot_track import Spot, Track
from plugins.humanoid.track import PanTiltTrack
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from runtime.resources.api import Bounds
from runtime.resources.spt import Context
from tests.memory_service import MemoryService
from tests.plugins.behaviors.closed_loop import BenchNavigation, SightDetector
from tests.plugins.humanoid.head_loop import plugin
from tests.plugins.humanoid.test_track_other_head import station
from tests.plugins.navigation.loop import ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel, room


def made(cls: type[Any], services: Mapping[str, Any], clock: list[float], written: list[Any], **params: str) -> Any:
    uses = tuple(Uses(service=f"S.{alias}", as_=alias) for alias in services)
    record = BehaviorRecord(name="LOOK", kind=cls.__name__.lower(), timeout=60.0, uses=uses,
                            params=tuple(Param(name=k, value=v) for k, v in params.items()),
                            outputs=(BehaviorOutput(name="seen", topic="/seen"),))
    behavior = cls(record, BehaviorContext(services=dict(services), inputs={}, outputs={"seen": written.append},
                                           now=lambda: clock[0]))
    behavior.start()
    return behavior


def test_spot_holds_the_labelled_object_and_places_it_with_the_robots_pose() -> None:
    detection, nav, clock, written = MemoryService("d"), MemoryService("n"), [0.0], list[Any]()
    spot = made(Spot, {"detection": detection, "nav": nav}, clock, written, label="parcel", holdTime="1",
                minReliability="0.6")
    nav.outputs["pose"] = {"pose": {"x": 2.0, "y": 1.0, "yaw": math.pi}}
    detection.outputs["objects"] = {"objects": [{"name": "box", "x": 1.0, "y": 0.0, "reliability": 0.9},
                                                {"shape": "cylinder", "texture": "parcel", "x": 1.0, "y": 0.5,
                                                 "z": 0.3, "reliability": 0.7}]}
    assert spot.step().progress == 0.0
    clock[0] = 0.5
    assert spot.step().progress == pytest.approx(0.5)
    detection.outputs["objects"]["objects"][1]["reliability"] = 0.4  # a gap: the hold starts again
    clock[0] = 0.6
    assert spot.step().progress == 0.0
    detection.outputs["objects"]["objects"][1]["reliability"] = 0.8
    for clock[0] in (0.7, 1.7):
        status = spot.step()
    assert status.done and written[0]["label"] == "cylinder" and written[0]["frame"] == "map"
    assert (written[0]["x"], written[0]["y"], written[0]["z"]) == pytest.approx((1.0, 0.5, 0.3))


def test_spot_over_the_fusion_takes_its_map_position_and_without_a_pose_keeps_the_detectors_frame() -> None:
    fusion, clock, written = MemoryService("f"), [0.0], list[Any]()
    spot = made(Spot, {"fusion": fusion}, clock, written, label="parcel")
    fusion.outputs["objects"] = {"objects": [{"name": "parcel", "frame": "map", "x": 3.0, "y": 4.0,
                                              "reliability": 0.9}]}
    assert spot.step().done and (written[0]["frame"], written[0]["x"]) == ("map", 3.0)
    detection, written = MemoryService("d"), list[Any]()
    spot = made(Spot, {"detection": detection}, clock, written, label="parcel")
    detection.outputs["objects"] = {"objects": [{"name": "parcel", "frame": "camera", "x": 0.2, "y": -0.1,
                                                 "z": 1.5, "reliability": 0.9}]}
    assert spot.step().done and (written[0]["frame"], written[0]["z"]) == ("camera", 1.5)


def test_spot_watches_exactly_one_perception_service() -> None:
    with pytest.raises(ParamError, match="it watches one perception service"):
        made(Spot, {"nav": MemoryService("n")}, [0.0], [])
    with pytest.raises(ParamError, match="one of the two"):
        made(Spot, {"detection": MemoryService("d"), "fusion": MemoryService("f")}, [0.0], [])


def test_track_counts_only_while_the_head_follows_the_labelled_target() -> None:
    head, clock, written = MemoryService("t"), [0.0], list[Any]()
    track = made(Track, {"track": head}, clock, written, label="parcel", holdTime="0.5")
    head.outputs["target"] = {"label": "box", "frame": "map", "x": 1.0, "y": 2.0, "z": 0.0, "reliability": 0.9}
    head.values["moving"] = 1
    assert track.step().progress == 0.0
    head.outputs["target"] = {**head.outputs["target"], "label": "parcel"}
    head.values["moving"] = 0
    assert track.step().progress == 0.0  # seen, but the head does not follow it
    head.values["moving"] = 1
    assert not track.step().done
    clock[0] = 0.5
    assert track.step().done and written[0]["label"] == "parcel" and written[0]["frame"] == "map"


class PanTiltService:
    """The real pan-tilt-track plugin as the service a behavior uses: each output read processes the
    detector's view of one object with the head where the plugin last sent it."""

    def __init__(self, plugin: PanTiltTrack, seen: Mapping[str, Any], tilt: float) -> None:
        self.plugin, self.seen, self.ref = plugin, seen, "Head.Track"
        self.head = {"pan": 0.0, "tilt": tilt}
        self.frames = 0
        self.result: dict[str, Any] = {}

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        return None

    def process(self) -> None:
        self.result = self.plugin.process({"objects": self.seen, "head_state": dict(self.head)},
                                          Context(self.frames, 0.1 * self.frames, "Head"))
        self.frames += 1
        self.head = dict(self.result.get("head_goal") or self.head)

    def output(self, name: str) -> Any:
        return self.result.get(name)

    def measures(self) -> dict[str, float]:
        return {"moving": float(self.result["moving"])} if "moving" in self.result else {}

    def samples(self, measure: str) -> list[float]:
        return []

    def running(self) -> bool:
        return True


@pytest.mark.parametrize("head", ["nao", "station_arm"])
def test_track_over_the_pan_tilt_kind_on_two_heads(head: str) -> None:
    tracker = plugin(PanTiltTrack, "pan-tilt-track", pose="1.0 1.0 0.5", planeHeight=0.0) if head == "nao" \
        else station()
    tracker.setup()
    try:
        seen = {"objects": [{"name": "parcel", "x": 0.6, "y": 0.55, "reliability": 0.8}], "reliability": 0.8,
                "width": 640, "height": 480}
        # the station's camera looks down at the floor with its elbow bent forward (its URDF), the Nao's level
        service, clock, written = PanTiltService(tracker, seen, 0.0 if head == "nao" else 2.0), [0.0], list[Any]()
        track = made(Track, {"track": service}, clock, written, label="parcel", holdTime="0.5")
        for frame in range(20):
            clock[0] = 0.1 * frame
            service.process()
            if track.step().done:
                break
        assert written and written[0]["label"] == "parcel" and written[0]["frame"] == "map"
        assert 0.5 <= clock[0] <= 1.0  # held half a second while the head followed it
    finally:
        tracker.stop()


@pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)
def test_in_the_closed_loop_spot_places_the_parcel_on_the_map(tmp_path: Path, model: RobotModel) -> None:
    bench = Bench(room(tmp_path), (1.0, 1.8, 0.3), model=model,
                  nav={"particles": 1000, "initialPose": "1 1.8 0.3", "initialSpread": "0.05 0.03"})
    try:
        eyes = SightDetector(bench, {"parcel": (1.9, 2.1), "box": (1.0, 0.8)})
        clock, written = [0.0], list[Any]()
        spot = made(Spot, {"detection": eyes, "nav": BenchNavigation(bench)}, clock, written, label="parcel",
                    holdTime="1")
        spot.context.now = lambda: bench.now
        assert bench.run(lambda: spot.step().done, 20.0)
        (found,) = written
        assert found["frame"] == "map" and math.dist((found["x"], found["y"]), (1.9, 2.1)) < 0.15
    finally:
        bench.close()


@pytest.mark.parametrize("head", ["nao", "station_arm"])
def test_track_object_then_fix_object_over_the_pan_tilt_kind_on_two_heads(head: str) -> None:
    """The lab's OBJ_TRACK and OBJ_FIX kinds on the Nao's head and on the station's turret: done once
    the head follows the target, then its map position (the tracker's) once the recognition held."""
    tracker = plugin(PanTiltTrack, "pan-tilt-track", pose="1.0 1.0 0.5", planeHeight=0.0) if head == "nao" \
        else station()
    tracker.setup()
    try:
        seen = {"objects": [{"name": "parcel", "x": 0.6, "y": 0.55, "reliability": 0.8}], "reliability": 0.8,
                "width": 640, "height": 480}
        service = PanTiltService(tracker, seen, 0.0 if head == "nao" else 2.0)
        recog = MemoryService("Camera.Recog")
        recog.outputs["objects"] = seen
        clock, written = [0.0], list[Any]()
        follow = made(TrackObject, {"recog": recog, "track": service}, clock, written, target="parcel")
        service.process()
        assert follow.step().done  # seen, and the head turning towards it
        fix = made(FixObject, {"recog": recog, "track": service}, clock, written, target="parcel", holdTime="0.5")
        for frame in range(1, 20):
            clock[0] = 0.1 * frame
            service.process()
            if fix.step().done:
                break
        (position,) = written
        target = service.output("target")
        assert position["frame"] == "map" and position["label"] == "parcel"
        assert (position["x"], position["y"]) == pytest.approx((target["x"], target["y"]))
        assert 0.6 <= clock[0] <= 0.8  # from the first reliable frame (0.1 s), half a second held
    finally:
        tracker.stop()


def test_fix_object_waits_while_the_recognition_is_below_its_reliability() -> None:
    recog = MemoryService("Camera.Recog")
    recog.outputs["objects"] = {"objects": [{"name": "parcel", "x": 0.1, "y": 0.0, "reliability": 0.5}]}
    clock, written = [0.0], list[Any]()
    fix = made(FixObject, {"recog": recog}, clock, written, target="parcel", holdTime="0.2")
    for frame in range(30):
        clock[0] = 0.1 * frame
        assert not fix.step().done
    assert written == []
    recog.outputs["objects"]["objects"][0]["reliability"] = 0.9
    clock[0] += 0.1
    fix.step()
    clock[0] += 0.3
    assert fix.step().done and written[0]["label"] == "parcel" and written[0]["frame"] == "camera"
