"""Navigation.AMCL's live outputs (issue K.5, D215) in the use case's lab (configs/usecase/environment.xml):
the particle cloud, a strided sample of the real filter's particles after each step on scans ray-cast
in the lab's grid, and the zoom-map area the Navigation holds, moved by the <ZoomMap> rules as the
robot drives; both fit their MessageTypes and the recording's ROS types."""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import ckmconf
from ckmconf.model import System
from plugins.localization.mcl import AmclFilter
from plugins.localization.raster import GridMap
from plugins.navigation.amcl import AmclNavigation
from plugins.navigation.frames import Pose, relative
from runtime.resources import codec
from runtime.resources.spt import Context
from runtime.ros.config import ConfigRosTypes
from runtime.ros.convert import to_message

from .test_amcl import grid, navigation, odometry, scan

ROOT = Path(__file__).resolve().parents[3]
ENVIRONMENT = ROOT / "configs" / "usecase" / "environment.xml"
HOME: Pose = (1.5, 1.5, 0.785)  # where nodes.xml places the Turtlebot, the Navigation's initialPose


@cache
def lab_grid() -> GridMap:
    return grid(ENVIRONMENT)


def lab_navigation(**params: object) -> AmclNavigation:
    return navigation(ENVIRONMENT, initialPose="1.5 1.5 0.785", initialSpread="0.2 0.1", **params)


def step(nav: AmclNavigation, truth: Pose, k: int, t: float) -> dict[str, Any]:
    """One Navigation frame for the robot at ``truth`` (odometry starting at 0 at HOME, exact)."""
    inputs = {"scan": scan(lab_grid(), truth), "odom": odometry(relative(HOME, truth))}
    result = nav.process(inputs, Context(k, t))
    return dict(codec.decode(codec.encode(result)))  # as the network carries it


@pytest.mark.parametrize("filter_name", ["reliability", "mcl"])
def test_the_cloud_is_a_strided_sample_of_the_filter_around_the_robot(filter_name: str) -> None:
    nav = lab_navigation(filter=filter_name)
    for k in range(3):
        result = step(nav, HOME, k, 0.8 * k)
    assert nav.localizer is not None
    particles = nav.localizer.filter.particles
    cloud = result["particles"]
    assert cloud["frame"] == "map" and cloud["stamp"] == pytest.approx(1.6) and cloud["total"] == 500
    index = np.unique(np.linspace(0, 499, 200).round().astype(int))
    assert len(index) == 200
    for name, column in (("x", 0), ("y", 1)):
        assert isinstance(cloud[name], np.ndarray) and cloud[name].dtype == np.float64
        assert np.array_equal(cloud[name], particles[index, column])
    assert np.allclose(np.cos(cloud["yaw"]), np.cos(particles[index, 2])) and np.all(np.abs(cloud["yaw"]) <= math.pi)
    f = nav.localizer.filter
    expected = f.weights[index] if isinstance(f, AmclFilter) else np.full(200, 1 / 500)  # Algorithm 3: all equal
    assert np.allclose(cloud["weight"], expected)
    # the cloud is where the robot is: its median within 15 cm of the truth, most particles within 0.5 m
    x, y = np.median(cloud["x"]), np.median(cloud["y"])
    assert math.hypot(x - HOME[0], y - HOME[1]) < 0.15
    assert np.mean(np.hypot(cloud["x"] - HOME[0], cloud["y"] - HOME[1]) < 0.5) > 0.8


def test_the_cloud_size_is_a_parameter_zero_publishing_none() -> None:
    small = lab_navigation(cloudSize=10)
    assert len(step(small, HOME, 0, 0.0)["particles"]["x"]) == 10
    whole = lab_navigation(particles=100, cloudSize=500)  # more asked than there are: every particle
    assert len(step(whole, HOME, 0, 0.0)["particles"]["x"]) == 100
    assert "particles" not in step(lab_navigation(cloudSize=0), HOME, 0, 0.0)


def test_the_zoom_area_follows_the_estimate_by_the_zoom_map_rules() -> None:
    """<ZoomMap mode="2.5D" width="4" depth="4" height="2" border="0.1" timeout="10"/> of the lab."""
    nav = lab_navigation()
    first = step(nav, HOME, 0, 0.0)
    zoom, estimate = first["zoom"], first["pose"]["pose"]
    assert zoom["reason"] == "start" and zoom["since"] == 0.0 and zoom["frame"] == "map"
    assert (zoom["x"], zoom["y"]) == (estimate["x"], estimate["y"])  # centred on the estimate
    assert (zoom["width"], zoom["depth"], zoom["height"], zoom["mode"]) == (4.0, 4.0, 2.0, "2.5D")
    assert "drop_table" in zoom["objects"] and "workbench" not in zoom["objects"]  # 1 m away; 7 m away
    assert zoom["avoided"] == sorted(zoom["avoided"])
    # driving east along y = 1.5: the area stays until the robot is within 0.4 m of its edge (x ≈ 3.1)
    t, k, moves = 0.0, 1, []
    for x in np.arange(1.7, 4.0, 0.2):
        t, k = t + 0.8, k + 1
        zoom = step(nav, (float(x), 1.5, 0.0), k, t)["zoom"]
        moves += [(round(float(x), 1), zoom["reason"])] if zoom["since"] == t else []
    assert moves and moves[0][1] == "border" and 3.0 <= moves[0][0] <= 3.4, moves
    # standing still: the area moves again after the 10 s timeout, not before
    since = zoom["since"]
    for _ in range(14):
        t, k = t + 0.8, k + 1
        zoom = step(nav, (3.9, 1.5, 0.0), k, t)["zoom"]
        if zoom["since"] != since:
            break
    assert zoom["reason"] == "timeout" and 10.0 <= zoom["since"] - since < 10.8
    # a copy restored from the state (delegation) holds the same area and goes on with the same messages
    copy = lab_navigation()
    copy.restore(codec.decode(codec.encode(nav.state())))
    mine, theirs = step(nav, (3.9, 1.5, 0.0), k + 1, t + 0.8), step(copy, (3.9, 1.5, 0.0), k + 1, t + 0.8)
    assert theirs["zoom"] == mine["zoom"]


def test_an_environment_without_a_zoom_map_publishes_no_area(tmp_path: Path) -> None:
    from .loop import room  # the test room has no <ZoomMap>

    file = room(tmp_path)
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.1 0.05")
    result = nav.process({"scan": scan(grid(file), (1.0, 1.8, 0.0)), "odom": odometry((0, 0, 0))}, Context(0, 0.0))
    assert "zoom" not in result and "particles" in result


@cache
def lab() -> System:
    return ckmconf.load(ROOT / "configs" / "usecase" / "lab.xml")


def test_the_use_case_publishes_them_on_typed_topics_the_recording_keeps() -> None:
    system = lab()
    (service,) = [s for r in system.resources if r.name == "Navigation" for s in r.services]
    outputs = {o.name: o.topic for o in service.outputs}
    assert outputs["particles"] == "/nav/particles" and outputs["zoom"] == "/nav/zoom"
    topics = {t.name: t for n in system.nodes for t in n.topics}
    assert topics["/nav/particles"].type == "ParticleCloud" and topics["/nav/zoom"].type == "ZoomArea"
    result = step(lab_navigation(), HOME, 0, 0.0)
    types = ConfigRosTypes(system)
    back: dict[str, Any] = {}
    for output, ckm_type in (("particles", "ParticleCloud"), ("zoom", "ZoomArea")):
        message_type = next(m for m in system.message_types if m.name == ckm_type)
        assert set(result[output]) == {f.name for f in message_type.fields}  # every field, no other
        ros_type = types.ros_type_of(ckm_type)
        assert ros_type == f"ckm_msgs/msg/{ckm_type}"  # what --record writes (runtime/ros/recording.py)
        message = to_message(types.ros, ros_type, types.payload(ros_type, result[output]))
        back[output] = types.ros.decode(ros_type, types.ros.encode(ros_type, message))
    assert np.array_equal(back["particles"].x, result["particles"]["x"]) and back["particles"].total == 500
    assert back["zoom"].objects == result["zoom"]["objects"] and back["zoom"].width == 4.0
    # 200 particles: 200 × 8 bytes a column on the wire, every 0.8 s
    assert len(codec.encode(result["particles"])["x"]["~nd"][2]) == 200 * 8
