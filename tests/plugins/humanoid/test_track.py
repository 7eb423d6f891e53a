"""plugin.pan-tilt-track (PanTiltCamera.Track, Table 7.2) on its messages: target choice, the speed
and joint limits on the head goal, the map position of the target, bad input and Parameters."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from plugins.humanoid.track import PanTiltTrack
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from runtime.ros.config import ConfigRosTypes
from runtime.ros.convert import to_message
from tests.conftest import CONFIGS

from .head_loop import plugin


@pytest.fixture
def track() -> Iterator[PanTiltTrack]:
    made: PanTiltTrack = plugin(PanTiltTrack, "pan-tilt-track", pose="5.0 4.0 1.2", planeHeight=0.3)
    made.setup()
    yield made
    made.stop()


def seen(*objects: dict[str, Any]) -> dict[str, Any]:
    return {"objects": list(objects), "reliability": 0.5, "width": 320, "height": 240}


def run(track: PanTiltTrack, objects: Any, head: Any = None, now: float = 0.0) -> dict[str, Any]:
    head = {"pan": 0.0, "tilt": 0.0} if head is None else head
    result: dict[str, Any] = track.process({"objects": objects, "head_state": head}, Context(0, now, "PanTiltCamera"))
    return result


def chosen(track: PanTiltTrack, objects: dict[str, Any]) -> str:
    found = track.choose(objects)
    return "" if found is None else str(found["name"])


def test_the_target_parameters_choose_the_object(track: PanTiltTrack) -> None:
    red = {"name": "cylinder_red_stripes", "x": 0.2, "y": 0.5, "reliability": 0.6}
    blue = {"name": "cylinder_blue_dots", "x": 0.8, "y": 0.5, "reliability": 0.9}
    box = {"name": "box_cereal", "shape": "box", "x": 0.5, "y": 0.5, "reliability": 0.95}
    assert chosen(track, seen(red, blue, box)) == "box_cereal"  # none asked: the most reliable
    track.apply_service_parameters({"target": "cylinder", "targetTexture": "red_stripes"})
    assert chosen(track, seen(red, blue, box)) == "cylinder_red_stripes"
    track.apply_service_parameters({"target": "box", "targetTexture": ""})
    assert chosen(track, seen(red, blue, box)) == "box_cereal"
    track.apply_service_parameters({"target": "sphere"})
    result = run(track, seen(red, blue, box))
    assert result["moving"] == 0 and result["track"]["in_view"] is False and "head_goal" not in result


def test_the_head_goal_turns_towards_the_target_at_most_speed_per_period(track: PanTiltTrack) -> None:
    left_up = {"name": "a", "x": 0.0, "y": 0.0, "reliability": 0.8}  # 0.42 rad left, 0.32 rad up
    track.apply_service_parameters({"speed": 0.2})
    first = run(track, seen(left_up), now=0.0)
    assert first["head_goal"] == {"pan": pytest.approx(0.1), "tilt": pytest.approx(-0.1)}  # 0.2 rad/s x 0.5 s
    assert first["moving"] == 1 and first["track"]["error"] > 0.4
    track.apply_service_parameters({"speed": 2.0})
    second = run(track, seen({**left_up, "reliability": 0.81}), now=0.1)  # 0.1 s later: 0.2 rad at most
    assert second["head_goal"]["pan"] == pytest.approx(0.2)
    centred = run(track, seen({"name": "a", "x": 0.501, "y": 0.5, "reliability": 0.8}), {"pan": 0.3, "tilt": 0.1},
                  now=0.2)
    assert centred["head_goal"] == {"pan": 0.3, "tilt": 0.1}  # within tolerance: hold
    assert centred["moving"] == 1 and centred["track"]["in_view"]


def test_the_head_goal_stays_within_the_joint_limits(track: PanTiltTrack) -> None:
    result = run(track, seen({"name": "a", "x": 0.0, "y": 1.0, "reliability": 0.8}), {"pan": 2.0, "tilt": 0.45})
    assert result["head_goal"] == {"pan": 2.0857, "tilt": 0.5149}


def test_a_repeated_result_does_not_move_the_head_twice(track: PanTiltTrack) -> None:
    objects = seen({"name": "a", "x": 0.2, "y": 0.5, "reliability": 0.8})
    goal = run(track, objects, now=0.0)["head_goal"]
    again = run(track, dict(objects), {"pan": 0.2, "tilt": 0.0}, now=0.5)
    assert again["head_goal"] == goal and again["moving"] == 1 and "track" in again


def test_the_target_lands_where_the_optical_axis_meets_the_plane(track: PanTiltTrack) -> None:
    tilt = 0.3  # the head looks down 0.3 rad; the object is at the image centre
    result = run(track, seen({"name": "a", "x": 0.5, "y": 0.5, "reliability": 0.7}), {"pan": 0.0, "tilt": tilt})
    # nao.urdf: the pitch joint 0.44 m up, the camera 0.07 m ahead of and 0.08 m above it
    cam_x = 0.07 * math.cos(tilt) + 0.08 * math.sin(tilt)
    cam_z = 0.44 + 0.08 * math.cos(tilt) - 0.07 * math.sin(tilt)
    ahead = cam_x + (cam_z - 0.3) / math.tan(tilt)
    target = result["target"]
    assert target["x"] == pytest.approx(5.0 + ahead * math.cos(1.2), abs=1e-3)
    assert target["y"] == pytest.approx(4.0 + ahead * math.sin(1.2), abs=1e-3)
    assert (target["z"], target["frame"], target["label"], target["reliability"]) == (pytest.approx(0.3), "map",
                                                                                      "a", 0.7)
    assert result["track"]["target"] == target
    level = run(track, seen({"name": "a", "x": 0.5, "y": 0.3, "reliability": 0.7}), now=0.5)  # above the horizon
    assert "target" not in level and level["track"]["target"] is None and level["moving"] == 1


def test_object_heights_come_from_the_environment_model() -> None:
    made: PanTiltTrack = plugin(PanTiltTrack, "pan-tilt-track", environment="environment.xml",
                                heights="box_cereal: 0.4")
    made.setup()
    try:
        assert made.heights["cylinder_red_stripes"] == pytest.approx(0.36)  # on the 0.30 m workbench, 0.12 m tall
        assert made.heights["workbench"] == pytest.approx(0.15)
        assert made.heights["box_cereal"] == 0.4  # the Param wins
    finally:
        made.stop()


def test_a_marking_lies_on_the_floor_and_a_2d_height_sets_the_centre(tmp_path: Path) -> None:
    """D294: a ``<Geometry2D height="0">`` marking's centre is on the floor, a 1.2 m one's 0.6 m up, and
    one of no height is the simulated world's 0.75 m block."""
    objects = "".join(
        f'<Object name="{name}" tag="thing"><Pose x="1" y="{i}" z="{z}"/><Geometry2D{height}>'
        '<Circle radius="0.2"/></Geometry2D></Object>'
        for i, (name, height, z) in enumerate(
            [
                ("pad", ' height="0"', 0.0),
                ("post", ' height="1.2"', 0.0),
                ("desk", "", 0.0),
                ("tray", ' height="0"', 0.5),
            ]
        )
    )
    environment = tmp_path / "environment.xml"
    environment.write_text(
        '<Part xmlns="urn:ckm:1" version="1.0"><Environment name="e"><Map xmin="0" ymin="-1" xmax="5" ymax="5"/>'
        f'<Semantic tag="thing"/>{objects}</Environment></Part>'
    )
    made: PanTiltTrack = plugin(PanTiltTrack, "pan-tilt-track", environment=str(environment))
    made.setup()
    try:
        assert made.heights == {"pad": 0.0, "post": pytest.approx(0.6), "desk": pytest.approx(0.375), "tray": 0.5}
    finally:
        made.stop()


@pytest.mark.parametrize(
    ("data", "error"),
    [
        ({"objects": {"items": []}, "head_state": {"pan": 0.0, "tilt": 0.0}}, "no 'objects' list"),
        ({"objects": seen(), "head_state": {"pan": "left", "tilt": 0.0}}, "head_state 'pan' = 'left'"),
        ({"objects": seen(), "head_state": [0.0, 0.0]}, "head_state is list, not a PanTilt"),
        ([1], "expects"),
    ],
)
def test_bad_input_is_named(track: PanTiltTrack, data: Any, error: str) -> None:
    with pytest.raises(ValueError, match="pan-tilt-track") as caught:
        track.process(data, Context(0, 0.0, ""))
    assert error in str(caught.value)


def test_objects_without_a_position_are_skipped_and_no_head_state_holds(track: PanTiltTrack) -> None:
    result = run(track, seen({"name": "a", "x": None, "y": 0.5}))
    assert result["track"]["in_view"] is False
    held = track.process({"objects": seen({"name": "a", "x": 0.1, "y": 0.5}), "head_state": None},
                         Context(0, 0.0, ""))
    assert "head_goal" not in held and held["track"]["head"] is None


def test_bad_parameters_are_refused(track: PanTiltTrack) -> None:
    for bad in (0.0, -1.0, "fast", True):
        with pytest.raises(ValueError, match="service parameter 'speed'"):
            track.apply_service_parameters({"speed": bad})
    with pytest.raises(ValueError, match="service parameter 'target'"):
        track.apply_service_parameters({"target": 3})
    with pytest.raises(ParamError, match="'pose'"):
        plugin(PanTiltTrack, "pan-tilt-track", pose="1 2")
    with pytest.raises(ParamError, match="'panMin'"):
        plugin(PanTiltTrack, "pan-tilt-track", panMin=1.0, panMax=0.0)
    with pytest.raises(ParamError, match="'heights'"):
        plugin(PanTiltTrack, "pan-tilt-track", heights="box 0.3")
    with pytest.raises(FileNotFoundError, match="robot model"):
        plugin(PanTiltTrack, "pan-tilt-track", model="none.urdf").setup()
    with pytest.raises(ValueError, match="cannot use environment file"):
        plugin(PanTiltTrack, "pan-tilt-track", environment="missing.xml").setup()
    with pytest.raises(RuntimeError, match="not set up"):
        plugin(PanTiltTrack, "pan-tilt-track").process({}, Context(0, 0.0, ""))


@pytest.mark.parametrize("in_view", [True, False])
def test_the_track_state_fits_the_use_cases_type_and_the_recording(track: PanTiltTrack, in_view: bool) -> None:
    """/pantilt/track is recorded as ckm_msgs/msg/TrackState: every field the plugin writes is declared."""
    system = ckmconf.load(CONFIGS / "usecase" / "lab.xml")
    red = {"name": "cylinder_red_stripes", "x": 0.3, "y": 0.6, "reliability": 0.7}
    state = run(track, seen(red) if in_view else seen(), now=1.0)["track"]
    declared = next(m for m in system.message_types if m.name == "TrackState")
    assert set(state) == {f.name for f in declared.fields}
    types = ConfigRosTypes(system)
    ros_type = types.ros_type_of("TrackState")
    message = to_message(types.ros, ros_type, types.payload(ros_type, state))
    back = types.ros.decode(ros_type, types.ros.encode(ros_type, message))
    assert back.in_view is in_view and back.label == ("cylinder_red_stripes" if in_view else "")
    assert back.error == pytest.approx(state["error"] or 0.0)
