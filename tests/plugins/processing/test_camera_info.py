"""Intrinsics from a ``sensor_msgs/CameraInfo`` input, carried with each frame through resize plugins
(issue M point 2; plugins/processing/camera_info.py).

``depth-acquisition`` with ``cameraInfo`` pairs the depth image with its CameraInfo; ``image-resize``
passes the CameraInfo on; the clustering, configured with no intrinsics at all, places the objects
with the CameraInfo's ``k``. Shown on two cameras (the lab's Xtion, 640 × 480, and a wider one of
non-square pixels and off-centre principal point, 800 × 600): the clusters land on the true objects,
and a CameraInfo of the other camera puts them elsewhere, so the CameraInfo is what is used.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from ckm_lab.shapes import XTION, render_depth_scene

import ckmconf
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.cameras import Camera
from plugins.processing.depth import DepthAcquisition, EuclideanClustering
from plugins.processing.image import Resize
from runtime.registry import Registry
from runtime.resources.spt import Context, Topology
from runtime.verification.verify import verify

CTX = Context(frame=0, stamp=0.0, resource="R")
OTHER = Camera(460.0, 455.0, 412.0, 291.5, 800, 600)
CAMERAS = {"xtion": XTION, "other": OTHER}


def record(kind: str, **params: object) -> Plugin:
    return Plugin(name=kind, kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in params.items()))


def camera_info(camera: Camera) -> dict[str, Any]:
    """The CameraInfo a ROS driver publishes for ``camera`` (field names of ROS 2)."""
    return {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "camera_optical"},
            "width": camera.width, "height": camera.height, "distortion_model": "plumb_bob", "d": np.zeros(5),
            "k": np.array([camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0])}


def image(depth_mm: np.ndarray[Any, Any], sec: int) -> dict[str, Any]:
    rows, cols = depth_mm.shape
    return {"header": {"stamp": {"sec": sec, "nanosec": 0}, "frame_id": "camera_optical"}, "height": rows,
            "width": cols, "encoding": "16UC1", "is_bigendian": 0, "step": 2 * cols,
            "data": depth_mm.astype("<u2").tobytes()}


@pytest.mark.parametrize("name", list(CAMERAS))
def test_the_clustering_places_objects_with_each_frame_s_camera_info_through_a_resize(name: str) -> None:
    camera, wrong = CAMERAS[name], CAMERAS["other" if name == "xtion" else "xtion"]
    scene = render_depth_scene(seed=2, resolution=(camera.height, camera.width), camera=camera, noise=False)
    acquisition = DepthAcquisition(record("depth-acquisition", cameraInfo="info"))
    resize = Resize(record("image-resize", width=camera.width // 2, interpolation="nearest"))
    clustering = EuclideanClustering(record("euclidean-clustering", tolerance=0.03, minPoints=100))
    assert clustering.camera is None  # no intrinsics configured: only the frames carry them
    frame = acquisition.process({"depth": image(scene.depth, 1), "info": camera_info(camera)}, CTX)
    half: Any = resize.process(frame, CTX)
    assert half["image"].shape == (camera.height // 2, camera.width // 2)
    assert half["camera_info"]["k"][0] == camera.fx
    clusters = clustering.process(half, CTX)
    assert len(clusters) == len(scene.truth)
    for cluster, truth in zip(clusters, scene.truth, strict=True):
        assert math.dist(cluster.centroid, (truth.x, truth.y, truth.z)) < 0.05
    # The other camera's CameraInfo with the same pixels: the objects land elsewhere.
    misinformed = acquisition.process({"depth": image(scene.depth, 2), "info": camera_info(wrong)}, CTX)
    misplaced = clustering.process(resize.process(misinformed, CTX), CTX)
    worst = max(math.dist(c.centroid, (t.x, t.y, t.z)) for c, t in zip(misplaced, scene.truth, strict=False))
    assert worst > 0.1


def test_nothing_is_produced_until_both_inputs_arrive_nor_twice_for_one_image() -> None:
    acquisition = DepthAcquisition(record("depth-acquisition", cameraInfo="info"))
    depth = np.full((4, 6), 1500, dtype=np.uint16)
    assert acquisition.process({"depth": image(depth, 1), "info": None}, CTX) is None
    assert acquisition.process({"depth": None, "info": camera_info(XTION)}, CTX) is None
    first = acquisition.process({"depth": image(depth, 1), "info": camera_info(XTION)}, CTX)
    assert first is not None and first["image"].dtype == np.float32
    assert float(first["image"][0, 0]) == pytest.approx(1.5)
    # Only the CameraInfo is new (it is published beside every image): the same image is not processed again.
    assert acquisition.process({"depth": image(depth, 1), "info": camera_info(XTION)}, CTX) is None
    assert acquisition.process({"depth": image(depth, 2), "info": camera_info(XTION)}, CTX) is not None


def test_a_malformed_or_uncalibrated_camera_info_is_refused_naming_the_plugin() -> None:
    acquisition = DepthAcquisition(record("depth-acquisition", cameraInfo="info"))
    depth = np.full((4, 6), 1500, dtype=np.uint16)
    uncalibrated = camera_info(XTION) | {"k": np.zeros(9)}  # what an uncalibrated driver publishes
    with pytest.raises(ValueError, match=r"plugin 'depth-acquisition' \(depth-acquisition\): the camera info gives "
                                         r"no camera .* an uncalibrated camera publishes k of zeros"):
        acquisition.process({"depth": image(depth, 1), "info": uncalibrated}, CTX)
    with pytest.raises(ValueError, match=r"'k' has 4 values, not 9"):
        acquisition.process({"depth": image(depth, 2), "info": camera_info(XTION) | {"k": [1, 0, 1, 0]}}, CTX)
    with pytest.raises(ValueError, match=r"expects its two Inputs, the depth image and 'info', got \['depth'\]"):
        acquisition.process({"depth": image(depth, 3)}, CTX)
    clustering = EuclideanClustering(record("euclidean-clustering"))
    with pytest.raises(ValueError, match=r"the frame carries no camera_info and no intrinsics are configured"):
        clustering.process(np.ones((4, 6), dtype=np.float32), CTX)


SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="camera-info">
  <Topic name="/camera/depth" type="bytes"/>
  <Topic name="/camera/camera_info" type="bytes"/>
  <Topic name="/clusters" type="bytes"/>
  <Node name="pc"/>
  <SmartResource name="R" node="pc">
    <Plugin name="acquire" kind="depth-acquisition">{acquire}</Plugin>
    <Plugin name="half" kind="image-resize"><Param name="scale" value="0.5"/></Plugin>
    <Plugin name="clusters" kind="euclidean-clustering"><Param name="minPoints" value="50"/></Plugin>
    <Profile name="p"><Use plugin="acquire"><Use plugin="half"><Use plugin="clusters"/></Use></Use></Profile>
    <Service name="S">
      <Input name="depth" topic="/camera/depth"/>{inputs}<Output name="clusters" topic="/clusters"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="p" profile="p"><Policy measure="latency" upper="0.1"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""
INFO_INPUT = '<Input name="info" topic="/camera/camera_info"/>'
RESOURCE = "/System[@name='camera-info']/SmartResource[@name='R']"


def load(tmp_path: Path, *, acquire: str, inputs: str = INFO_INPUT) -> tuple[Path, Any]:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.format(acquire=acquire, inputs=inputs), encoding="utf-8")
    return path, ckmconf.load(path)


def problems(tmp_path: Path, **parts: str) -> list[str]:
    _, system = load(tmp_path, **parts)
    return [str(error) for error in verify(system, Registry(packages=("ckm",)))]


def test_verify_accepts_the_pairing_and_refuses_each_mistake_at_its_file_line_column(tmp_path: Path) -> None:
    paired = '<Param name="cameraInfo" value="info"/>'
    assert problems(tmp_path, acquire=paired) == []
    file = tmp_path / "system.xml"
    column = 'value="inf"'
    found = problems(tmp_path, acquire='<Param name="cameraInfo" value="inf"/>')
    col = file.read_text().splitlines()[7].index(column) + 1
    assert found == [f"{file}:8:{col}: {RESOURCE}/Plugin[@name='acquire']/Param[@name='cameraInfo']/@value: "
                     "plugin 'acquire' (depth-acquisition): Param 'cameraInfo' = 'inf' names no Input of the "
                     "stream's services (their Inputs: depth, info)"]
    found = problems(tmp_path, acquire='<Param name="cameraInfo" value="depth"/>', inputs="")
    assert len(found) == 1 and "the stream reads two Inputs, the depth image and its CameraInfo; it has 1: depth" \
        in found[0]
    # Without the pairing, the clustering has no intrinsics at all: refused at its Plugin element.
    found = problems(tmp_path, acquire="", inputs="")
    assert found == [f"{file}:10:5: {RESOURCE}/Plugin[@name='clusters']: plugin 'clusters' (euclidean-clustering): "
                     "give the camera's intrinsics: Params fx, calibrationWidth and calibrationHeight (missing: fx, "
                     "calibrationWidth, calibrationHeight), or camera naming its HWChannel"]


def test_a_topology_built_from_the_configuration_runs_the_camera_frames(tmp_path: Path) -> None:
    """The stream hands the acquisition ``{input: value}`` (runtime.resources.stream.newest_of); a frame
    for which it has nothing runs nothing below it and gives the service no output."""
    _, system = load(tmp_path, acquire='<Param name="cameraInfo" value="info"/>')
    topology = Topology(system.resources[0], Registry(packages=("ckm",)))
    topology.setup()
    try:
        topology.select("S", "p")
        scene = render_depth_scene(seed=3, resolution=(OTHER.height, OTHER.width), camera=OTHER, noise=False)
        done = topology.run({"depth": image(scene.depth, 7), "info": camera_info(OTHER)})
        assert len(done.outputs["S"]) == len(scene.truth)
        again = topology.run({"depth": image(scene.depth, 7), "info": camera_info(OTHER)})
        assert again.outputs == {"S": None}
        assert topology.stats()["clusters"].calls == 1
    finally:
        topology.stop()
