"""plugin.pan-tilt-track on a second robot model (issue M, point 6): the station arm's turret and elbow
carrying its wrist camera, configured by Params alone; the joint limits come from its URDF."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.humanoid.track import PanTiltTrack
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

STATION = {"model": "station_arm", "panJoint": "turret_joint", "tiltJoint": "elbow_joint",
           "camera": "wrist_camera_optical_frame", "fov": 1.0, "pose": "1.0 2.0 0.3", "planeHeight": 0.0}


def station(**params: object) -> PanTiltTrack:
    given = tuple(Param(name=k, value=str(v)) for k, v in {**STATION, **params}.items())
    return PanTiltTrack(Plugin(name="track", kind="pan-tilt-track", params=given))


@pytest.fixture
def track() -> Iterator[PanTiltTrack]:
    made = station()
    made.setup()
    yield made
    made.stop()


def seen(x: float, y: float) -> dict[str, object]:
    return {"objects": [{"name": "parcel", "x": x, "y": y, "reliability": 0.8}], "reliability": 0.8,
            "width": 640, "height": 480}


def test_the_limits_are_the_urdf_joints_unless_given(track: PanTiltTrack) -> None:
    assert track.limits == ((-3.0, 3.0), (-2.5, 2.5))
    narrowed = station(panMin=-1.0)
    narrowed.setup()
    try:
        assert narrowed.limits == ((-1.0, 3.0), (-2.5, 2.5))
    finally:
        narrowed.stop()


def test_a_centred_object_is_placed_where_the_optical_axis_meets_the_floor(track: PanTiltTrack) -> None:
    pan, tilt = 0.5, 2.0
    result = track.process({"objects": seen(0.5, 0.5), "head_state": {"pan": pan, "tilt": tilt}}, Context(0, 0.0, ""))
    # the URDF: turret at 0.8 m, shoulder 0.1 m above it, elbow 0.4 m above that, camera 0.31 m along the
    # fore link; the elbow turns the fore link (and the camera's z axis) from up towards the front
    reach, height = 0.31 * math.sin(tilt), 1.3 + 0.31 * math.cos(tilt)  # the camera, ahead and up
    down_to_floor = height / -math.cos(tilt)  # along the axis (sin tilt ahead, cos tilt up) to z = 0
    ahead = reach + down_to_floor * math.sin(tilt)
    heading = 0.3 + pan
    expected = (1.0 + ahead * math.cos(heading), 2.0 + ahead * math.sin(heading))
    target = result["target"]
    assert target["frame"] == "map" and target["label"] == "parcel"
    assert (target["x"], target["y"], target["z"]) == pytest.approx((*expected, 0.0), abs=1e-6)
    assert "head_goal" not in result or result["head_goal"] == pytest.approx({"pan": pan, "tilt": tilt})


def test_an_object_to_the_right_turns_the_turret_right_within_its_urdf_limit(track: PanTiltTrack) -> None:
    result = track.process({"objects": seen(0.9, 0.5), "head_state": {"pan": -2.99, "tilt": 2.0}},
                           Context(0, 0.0, ""))
    goal = result["head_goal"]
    assert goal["pan"] == pytest.approx(-3.0)  # clipped at the turret's lower limit
    assert result["moving"] == 1


def test_a_model_without_the_named_joint_is_refused_at_setup() -> None:
    wrong = station(panJoint="HeadYaw")
    with pytest.raises(ValueError, match="has no joint or link HeadYaw"):
        wrong.setup()


def test_the_head_is_not_defaulted_to_any_robot() -> None:
    given = tuple(Param(name=k, value=str(v)) for k, v in {"pose": "0 0 0"}.items())
    with pytest.raises(ParamError, match="needs parameter 'model'"):
        PanTiltTrack(Plugin(name="track", kind="pan-tilt-track", params=given))
