"""The standard interfaces' message types (issue M point 1; D276–D279).

Every port's types are ROS 2 standard types or ones of the shipped ``ckm_interfaces`` package; the
package loads from a configuration anywhere, validates, encodes to CDR and records; what the
standard kinds write (run here on two robot models where they have a robot) is what they declare,
and crosses the CDR encoder of its port's type and back with every field it carries.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import ckmconf
from ckmconf.model import Param, System
from ckmconf.model.resources import Plugin
from ckmconf.rostypes import SHIPPED, shipped_ros_types, standard_ros_types
from plugins.localization.estimate import Estimate
from plugins.navigation.laser_scan import LaserScanService
from plugins.processing.fusion import FeatureFusion
from runtime.resources.spt import Context
from runtime.ros.bag import BagRecorder, BagSource
from runtime.ros.config import ConfigRosTypes
from runtime.ros.interface_types import ADAPTATIONS, yaw_of
from runtime.ros.wire import CdrWire
from runtime.verification.interfaces import STANDARD, writes_of
from tests.plugins.navigation.loop import TURTLEBOT, plugin, room
from tests.plugins.navigation.test_amcl import ROVER, frames, grid, navigation
from tests.plugins.navigation.test_displacement import Unicycle, base, move


def fusion_result() -> dict[str, Any]:
    """What feature-fusion writes for a texture seen by a camera and a shape by a depth sensor, one object."""
    params = {"inputs": "rgb: line; depth: point", "objects": "red_can: cylinder red_stripes", "fx": 525,
              "calibrationWidth": 640, "calibrationHeight": 480}
    fusion = FeatureFusion(Plugin(name="f", kind="feature-fusion",
                                  params=tuple(Param(name=k, value=str(v)) for k, v in params.items())))
    x, y, z = 0.1, 0.05, 1.2
    line = {"name": "red_can", "matches": 40, "inliers": 30, "reliability": 0.65,
            "x": (525.0 * x / z + 319.5) / 640, "y": (525.0 * y / z + 239.5) / 480}
    point = {"name": "cylinder", "reliability": 0.8, "x": x, "y": y, "z": z - 0.03, "points": 400}
    out = fusion.process({"rgb": {"objects": [line], "reliability": 0.65, "keypoints": 500, "width": 640,
                                  "height": 480},
                          "depth": {"objects": [point], "reliability": 0.8}}, Context(0, 0.0))
    assert len(out["objects"]) == 1, out
    return out


def typed(tmp_path: Path, **topics: str) -> System:
    """A system of nothing but ``topics`` (name without its slash → type), in a folder of its own."""
    body = "".join(f'<Topic name="/{name}" type="{kind}"/>' for name, kind in topics.items())
    path = tmp_path / "elsewhere" / "system.xml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(f'<System xmlns="urn:ckm:1" version="1.0" name="typed">{body}<Node name="n"/></System>')
    return ckmconf.load(str(path))


def across(wire: CdrWire, type_name: str, value: Any) -> dict[str, Any]:
    """``value`` encoded as a CDR ``type_name`` message and decoded back (the ROS fields)."""
    data = wire.encode(type_name, value)
    assert data[:4] == b"\x00\x01\x00\x00"
    decoded = wire.payload_of(type_name, data)
    assert isinstance(decoded, dict)
    return decoded


def paths(value: Mapping[str, Any], prefix: str = "") -> set[str]:
    """The field paths of a written value (``pose.x``, ``objects[].name``), leaves only."""
    found: set[str] = set()
    for key, item in value.items():
        here = f"{prefix}{key}"
        if isinstance(item, Mapping):
            found |= paths(item, f"{here}.")
        elif isinstance(item, list) and item and all(isinstance(i, Mapping) for i in item):
            for element in item:
                found |= paths(element, f"{here}[].")
        else:
            found.add(here)
    return found


def covered(written: set[str], declared: tuple[str, ...]) -> set[str]:
    """The written paths no declared field (or a parent of one) names."""
    return {p for p in written if not any(p == d or p.startswith((f"{d}.", f"{d}[].")) for d in declared)}


# ---------------------------------------------------------------------- the types and the package


def test_every_port_type_is_a_ros_2_standard_type_or_a_shipped_one() -> None:
    known = standard_ros_types() | set(shipped_ros_types())
    typed_ports = [(i.name, p) for i in STANDARD.values() for p in (*i.inputs, *i.outputs) if p.messages]
    assert len(typed_ports) >= 10
    for interface, port in typed_ports:
        assert set(port.messages) <= known, f"{interface} {port.name}: {port.messages}"
        assert port.fields, f"{interface} {port.name} names its types but not its fields"
    assert STANDARD["laser-scan"].outputs[0].messages == ("sensor_msgs/msg/LaserScan",)
    assert STANDARD["base-drive"].port("odom", 2).messages == ("nav_msgs/msg/Odometry",)  # type: ignore[union-attr]
    assert STANDARD["navigation"].port("pose", 2).messages[0] == "geometry_msgs/msg/PoseWithCovarianceStamped"  # type: ignore[union-attr]


def test_every_topic_port_names_its_message_types() -> None:
    """Issue M: each interface with its message types (an interface added later types its ports too:
    ckm_interfaces/msg/GripperCommand and GripperStatus are there for a gripper)."""
    untyped = {(i.name, p.name) for i in STANDARD.values() for p in (*i.inputs, *i.outputs) if not p.messages}
    assert untyped <= {("map-sharing", "objects")}, f"ports without message types: {sorted(untyped)}"


def test_the_shipped_package_is_a_ros_package_whose_types_all_load(tmp_path: Path) -> None:
    names = shipped_ros_types()
    assert {"ckm_interfaces/msg/Detections", "ckm_interfaces/msg/GripperCommand", "ckm_interfaces/msg/GripperStatus",
            "ckm_interfaces/msg/NavigationStatus", "ckm_interfaces/msg/ArmStatus"} <= set(names)
    assert "<name>ckm_interfaces</name>" in (SHIPPED / "ckm_interfaces" / "package.xml").read_text()
    assert "rosidl_generate_interfaces" in (SHIPPED / "ckm_interfaces" / "CMakeLists.txt").read_text()
    system = typed(tmp_path, **{f"t{i}": name for i, name in enumerate(names)})
    types = ConfigRosTypes(system)
    assert types.problems == {}
    for name in names:
        assert types.ros.rihs01(name).startswith("RIHS01_")
    assert "ObjectDetection[] objects" in types.ros.msgdef("ckm_interfaces/msg/Detections")


def test_a_shipped_type_validates_from_any_folder_and_an_unknown_one_of_its_package_does_not(tmp_path: Path) -> None:
    assert typed(tmp_path, objects="ckm_interfaces/msg/Detections").topics[0].type == "ckm_interfaces/msg/Detections"
    with pytest.raises(ckmconf.ConfigError, match=r"unknown ROS 2 message type 'ckm_interfaces/msg/Nothing'"):
        typed(tmp_path, objects="ckm_interfaces/msg/Nothing")


def test_detections_encode_to_cdr_and_record_like_a_standard_type(tmp_path: Path) -> None:
    system = typed(tmp_path, objects="ckm_interfaces/msg/Detections")
    wire = CdrWire(ConfigRosTypes(system), system)
    assert wire.topic_type("/objects") == "ckm_interfaces/msg/Detections"
    written = fusion_result()
    back = across(wire, "ckm_interfaces/msg/Detections", written)
    (obj,) = back["objects"]
    (fused,) = written["objects"]
    for name in ("name", "shape", "texture", "frame", "observations"):
        assert obj[name] == fused[name]
    assert [obj["x"], obj["y"], obj["z"], obj["reliability"]] == pytest.approx(
        [fused["x"], fused["y"], fused["z"], fused["reliability"]])
    assert list(obj["sources"]) == fused["sources"] and list(obj["centre"]) == pytest.approx(fused["centre"])
    with BagRecorder(tmp_path / "bag", types=wire.types.ros) as bag:
        bag.add_topic("/objects", "ckm_interfaces/msg/Detections")
        bag.write("/objects", wire.types.payload("ckm_interfaces/msg/Detections", written), 1_700_000_000.0)
    (message,) = list(BagSource(tmp_path / "bag", types=wire.types.ros).messages())
    assert message.payload["objects"][0]["name"] == fused["name"]


# ---------------------------------------------------------------------- what the kinds write, through their types


@pytest.mark.parametrize(("steps", "fov", "range_max"), [(683, 4.1888, 5.6), (360, 2 * math.pi * 359 / 360, 12.0)])
def test_laser_scan_publishes_a_sensor_msgs_laser_scan_with_its_stamp_in_the_header(
    tmp_path: Path, steps: int, fov: float, range_max: float
) -> None:
    """The Turtlebot's URG-04LX and the rover's 360° lidar."""
    scanner: LaserScanService = plugin("laser-scan", LaserScanService, fov=fov, rangeMax=range_max)
    ranges = np.linspace(0.5, range_max + 1.0, steps)
    ranges[3] = np.nan
    out = scanner.process({"stamp": 1_700_000_000.25, "ranges": ranges}, Context(0, 0.0))
    assert covered(paths(out), STANDARD["laser-scan"].outputs[0].fields) == set()
    system = typed(tmp_path, scan="sensor_msgs/msg/LaserScan")
    back = across(CdrWire(ConfigRosTypes(system), system), "sensor_msgs/msg/LaserScan", out)
    assert back["header"]["stamp"] == pytest.approx(out["stamp"], abs=1e-9)
    np.testing.assert_array_equal(back["ranges"], out["ranges"])  # inf, -inf and nan as REP 117 has them
    for name in ("angle_min", "angle_max", "angle_increment", "scan_time", "range_min", "range_max"):
        assert back[name] == pytest.approx(out[name], rel=1e-6)


@pytest.mark.parametrize("params", [{"speed": 0.3}, {"speed": 0.6, "maxAngular": 1.0, "accel": 0.8}])
def test_base_drive_odometry_is_a_nav_msgs_odometry_and_its_move_status_a_shipped_type(
    tmp_path: Path, params: dict[str, float]
) -> None:
    """The Kobuki's limits and the rover's."""
    robot, service = Unicycle((1.0, 2.0, 0.3)), base(**params)
    out: dict[str, Any] = {}
    for k in range(20):
        out = robot.frame(service, move_goal=move(1, 0.5) if k == 0 else None)
    drive = STANDARD["base-drive"]
    for name in ("odom", "move_status"):
        assert covered(paths(out[name]), drive.port(name, 2).fields) == set()  # type: ignore[union-attr]
    system = typed(tmp_path, odom="nav_msgs/msg/Odometry", status="ckm_interfaces/msg/MoveStatus")
    wire = CdrWire(ConfigRosTypes(system), system)
    odom, back = out["odom"], across(wire, "nav_msgs/msg/Odometry", out["odom"])
    pose = back["pose"]["pose"]
    assert [pose["position"]["x"], pose["position"]["y"], yaw_of(pose["orientation"])] == pytest.approx(
        [odom["pose"]["x"], odom["pose"]["y"], odom["pose"]["yaw"]])
    assert back["header"]["stamp"] == pytest.approx(odom["stamp"])
    twist = back["twist"]["twist"]
    assert [twist["linear"]["x"], twist["angular"]["z"]] == pytest.approx(
        [odom["twist"]["linear"], odom["twist"]["angular"]])
    covariance = back["pose"]["covariance"]
    assert math.sqrt(covariance[0] + covariance[7]) == pytest.approx(odom["dispersion"])
    assert across(wire, "ckm_interfaces/msg/MoveStatus", out["move_status"]) == pytest.approx(out["move_status"])


@pytest.mark.parametrize("footprint", [TURTLEBOT, ROVER], ids=["turtlebot", "rover"])
def test_navigation_pose_and_status_cross_their_types(tmp_path: Path, footprint: dict[str, object]) -> None:
    file = room(tmp_path)
    world, truth = grid(file), (1.0, 1.8, 0.0)
    nav = navigation(file, goal="Target", **footprint)
    out = frames(nav, world, truth, truth)
    port = STANDARD["navigation"]
    for name in ("pose", "status"):
        assert covered(paths(out[name]), port.port(name, 2).fields) == set()  # type: ignore[union-attr]
    system = typed(tmp_path, pose="geometry_msgs/msg/PoseWithCovarianceStamped",
                   estimate="ckm_interfaces/msg/PoseEstimate", status="ckm_interfaces/msg/NavigationStatus")
    wire = CdrWire(ConfigRosTypes(system), system)
    estimate, back = out["pose"], across(wire, "geometry_msgs/msg/PoseWithCovarianceStamped", out["pose"])
    pose = back["pose"]["pose"]
    assert [pose["position"]["x"], pose["position"]["y"], yaw_of(pose["orientation"])] == pytest.approx(
        [estimate["pose"]["x"], estimate["pose"]["y"], estimate["pose"]["yaw"]])
    full = np.asarray(back["pose"]["covariance"]).reshape(6, 6)
    np.testing.assert_allclose(full[np.ix_([0, 1, 5], [0, 1, 5])].ravel(), estimate["covariance"])
    kept = across(wire, "ckm_interfaces/msg/PoseEstimate", estimate)  # every field, the dispersion too
    assert kept["dispersion"] == pytest.approx(estimate["dispersion"])
    assert list(kept["covariance"]) == pytest.approx(estimate["covariance"])
    status = across(wire, "ckm_interfaces/msg/NavigationStatus", out["status"])
    words = ("goal", "state", "reason")
    assert {k: status[k] for k in words} == {k: out["status"][k] for k in words}


def test_the_localization_estimate_becomes_a_pose_with_covariance(tmp_path: Path) -> None:
    from plugins.localization.service import Localization

    written = {**Estimate(np.array([2.0, -1.0, 3.0]), np.diag([0.04, 0.09, 0.01]), 0.3).as_message(),
               "filter": "mcl", "reliability": None}  # as Localization.process returns it
    assert covered(paths(written), writes_of(Localization)["pose"]) == set()
    system = typed(tmp_path, pose="geometry_msgs/msg/PoseWithCovarianceStamped")
    back = across(CdrWire(ConfigRosTypes(system), system), "geometry_msgs/msg/PoseWithCovarianceStamped", written)
    assert yaw_of(back["pose"]["pose"]["orientation"]) == pytest.approx(3.0)
    covariance = back["pose"]["covariance"]
    assert (covariance[0], covariance[7], covariance[35]) == pytest.approx((0.04, 0.09, 0.01))
    assert set(ADAPTATIONS["geometry_msgs/msg/PoseWithCovarianceStamped"].dropped) >= {"filter", "reliability"}


def test_a_value_already_in_the_ros_shape_passes_unchanged(tmp_path: Path) -> None:
    system = typed(tmp_path, odom="nav_msgs/msg/Odometry")
    ros = {"header": {"stamp": 5.0, "frame_id": "odom"}, "child_frame_id": "base_link",
           "pose": {"pose": {"position": {"x": 1.0}, "orientation": {"w": 1.0}}}}
    back = across(CdrWire(ConfigRosTypes(system), system), "nav_msgs/msg/Odometry", ros)
    assert (back["header"]["frame_id"], back["child_frame_id"], back["pose"]["pose"]["position"]["x"]) == (
        "odom", "base_link", 1.0)


def test_a_field_no_adaptation_knows_still_fails_the_encoder_naming_it(tmp_path: Path) -> None:
    system = typed(tmp_path, odom="nav_msgs/msg/Odometry")
    with pytest.raises(ValueError, match="wheel_ticks"):
        CdrWire(ConfigRosTypes(system), system).encode(
            "nav_msgs/msg/Odometry", {"stamp": 1.0, "pose": {"x": 0, "y": 0, "yaw": 0}, "wheel_ticks": 3})


@pytest.mark.parametrize("params", [{"speed": 0.3}, {"speed": 0.6, "maxAngular": 1.0, "accel": 0.8}])
def test_a_move_goal_received_as_ckm_interfaces_move_goal_drives_the_base(
    tmp_path: Path, params: dict[str, float]
) -> None:
    """A goal from a ROS 2 node (its unset yaw_tolerance 0: the service's own), on the Kobuki's and the rover's
    limits."""
    system = typed(tmp_path, move="ckm_interfaces/msg/MoveGoal")
    wire = CdrWire(ConfigRosTypes(system), system)
    goal = across(wire, "ckm_interfaces/msg/MoveGoal", {"id": 4, "frame": "robot", "x": 0.4, "y": 0.0, "yaw": 0.0})
    assert goal["yaw_tolerance"] == 0.0
    robot, service = Unicycle((0.0, 0.0, 0.0)), base(**params)
    status: dict[str, Any] = {}
    for _ in range(300):
        status = robot.frame(service, move_goal=goal)["move_status"]
        if status["state"] != "moving":
            break
    assert (status["id"], status["state"]) == (4, "done") and robot.x == pytest.approx(0.4, abs=0.05)
