"""The depth pipeline on a second robot model (issue M, point 6): the station arm's wrist camera.

``depth-acquisition → tabletop-clustering | euclidean-clustering → kdtree-shape-classifier``, configured
by Params alone for the station's own camera (320 × 240, 87° field of view: configs/examples/sim_station.xml's
``wrist_camera``), looking down at a work table from above — a viewpoint the lab's Xtion never has. On
the table stand a box and a cylinder of the sizes the shape model was trained on (the lab's model:
``lab_objects_shapes.pcd``). The depth image is the simulator's render in millimetres, as the sim
channel gives it. Each object must be classified by its shape, where it truly stands.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest

import ckmconf
from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.depth import DepthAcquisition, EuclideanClustering, KdTreeShapeClassifier
from plugins.processing.tabletop import TabletopClustering
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from tests.conftest import CONFIGS

WIDTH, HEIGHT, FOV = 320, 240, 1.5184
"""The station's wrist camera (sim_station.xml)."""

OBJECTS = {"cylinder": (1.55, 0.9, 0.78), "box": (1.6, 1.12, 0.795)}
"""Where each object's centre stands on the table (map frame)."""

STATION = f"""<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0" description="a work table before the station arm">
  <Environment name="station" frame="map">
    <Map xmin="0" ymin="0" xmax="4" ymax="3" height="2"/>
    <Semantic tag="table" landmark="landmark" dynamic="static"/>
    <Semantic tag="box" landmark="free" dynamic="static"/>
    <Semantic tag="cylinder" landmark="free" dynamic="static"/>
    <Object name="table" tag="table"><Pose x="1.6" y="1.0"/>
      <Geometry3D><Prism zmin="0.68" zmax="0.72"><Rectangle width="0.8" depth="0.6"/></Prism>
        <Prism zmin="0" zmax="0.68"><Rectangle width="0.1" depth="0.1"/></Prism></Geometry3D></Object>
    <Object name="cylinder" tag="cylinder"><Pose x="{OBJECTS['cylinder'][0]}" y="{OBJECTS['cylinder'][1]}" z="0.72"/>
      <Geometry25D><Prism zmax="0.12"><Circle radius="0.035"/></Prism></Geometry25D></Object>
    <Object name="box" tag="box"><Pose x="{OBJECTS['box'][0]}" y="{OBJECTS['box'][1]}" z="0.72"/>
      <Geometry25D><Prism zmax="0.15"><Rectangle width="0.06" depth="0.08"/></Prism></Geometry25D></Object>
  </Environment>
</Part>"""


def plugin(cls: type[Any], kind: str, **params: object) -> Any:
    made = cls(Plugin(name=kind, kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in params.items())))
    made.setup()
    return made


@pytest.fixture(scope="module")
def view(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[np.ndarray[Any, Any], Any, Any]]:
    """The wrist camera's depth frame (uint16 mm) over the table, and the camera's map rotation and position."""
    path: Path = tmp_path_factory.mktemp("station") / "station.xml"
    path.write_text(STATION)
    environment = ckmconf.load(path).environment
    assert environment is not None
    world = World(environment, seed=1)
    try:
        arm = Robot(world, "station_arm", world.load_robot("station_arm", "station_arm", (1.0, 1.0, 0.0)))
        for joint, angle in (("shoulder_joint", 0.3), ("elbow_joint", 1.9)):  # leaning over the table
            p.resetJointState(arm.body, arm.joint(joint), angle, physicsClientId=world.client)
        camera = Camera(arm, "wrist_camera_optical_frame", fov=FOV)
        depth = camera.render(WIDTH, HEIGHT).depth
        millimetres = np.where(depth < 3.0, np.rint(depth * 1000.0), 0).astype(np.uint16)  # beyond range: no return
        position, orientation = arm.link_pose(arm.link("wrist_camera_optical_frame"))
        rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        yield millimetres, rotation, np.asarray(position)
    finally:
        world.close()


def intrinsics() -> dict[str, float]:
    focal = (WIDTH / 2) / math.tan(FOV / 2)
    return {"fx": focal, "fy": focal, "cx": (WIDTH - 1) / 2, "cy": (HEIGHT - 1) / 2, "calibrationWidth": WIDTH,
            "calibrationHeight": HEIGHT}


@pytest.mark.parametrize("clustering", ["tabletop-clustering", "euclidean-clustering"])
def test_the_station_s_depth_pipeline_names_each_shape_where_it_stands(
        view: tuple[np.ndarray[Any, Any], Any, Any], clustering: str) -> None:
    frame, rotation, position = view
    context = Context(0, 0.0, "StationCamera")
    cls = TabletopClustering if clustering == "tabletop-clustering" else EuclideanClustering
    pipeline = [plugin(DepthAcquisition, "depth-acquisition", scale=0.001),
                plugin(cls, clustering, tolerance=0.03, minPoints=60, **intrinsics()),
                plugin(KdTreeShapeClassifier, "kdtree-shape-classifier", k=5, threshold=0.75,
                       model=CONFIGS / "usecase" / "models" / "lab_objects_shapes.pcd")]
    value: Any = frame
    for step in pipeline:
        value = step.process(value, context)
    named = [o for o in value["objects"] if o["name"] != "unknown"]
    for shape, centre in OBJECTS.items():
        truth = rotation.T @ (np.asarray(centre) - position)  # in the camera's optical frame
        near = [o for o in named if math.dist((o["x"], o["y"], o["z"]), truth) < 0.06]
        assert [o["name"] for o in near] == [shape], (shape, truth, named)
        assert near[0]["reliability"] >= 0.75


def test_the_intrinsics_can_come_from_the_camera_s_own_channel(view: tuple[np.ndarray[Any, Any], Any, Any]) -> None:
    """``camera`` names sim_station.xml's ``wrist_camera`` (160 × 120, 87°): its pinhole, scaled to the
    320 × 240 frame, is the one the Params state, and the clusters are the same."""
    frame, _, _ = view
    context = Context(0, 0.0, "StationCamera")
    depth = plugin(DepthAcquisition, "depth-acquisition", scale=0.001).process(frame, context)
    station = Loc(str(CONFIGS / "examples" / "sim_station.xml"), 1, 1, "/Plugin")
    by_channel = TabletopClustering(Plugin(name="c", kind="tabletop-clustering", loc=station, params=(
        Param(name="camera", value="wrist_camera"), Param(name="tolerance", value="0.03"),
        Param(name="minPoints", value="60"))))
    by_params = plugin(TabletopClustering, "tabletop-clustering", tolerance=0.03, minPoints=60, **intrinsics())
    assert by_channel.camera is not None and by_params.camera is not None
    assert by_channel.camera.intrinsics(HEIGHT, WIDTH) == pytest.approx(by_params.camera.intrinsics(HEIGHT, WIDTH))
    ours, theirs = by_channel.process(depth, context), by_params.process(depth, context)
    assert [c.points.shape for c in ours] == [c.points.shape for c in theirs] and len(ours) >= 2
    with pytest.raises(ParamError, match=r"Param 'camera' = 'wrist_cam': no HWChannel of that name"):
        TabletopClustering(Plugin(name="c", kind="tabletop-clustering", loc=station,
                                  params=(Param(name="camera", value="wrist_cam"),)))
    with pytest.raises(ParamError, match=r"give the camera's intrinsics: Params fx, calibrationWidth"):
        TabletopClustering(Plugin(name="c", kind="tabletop-clustering", params=(Param(name="fx", value="300"),)))
