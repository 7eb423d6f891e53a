"""Camera intrinsics come from the configuration, never from the lab (issue M, point 2).

The frames that reach the depth and fusion plugins carry no intrinsics (arrays after the acquisition
and resize plugins; recognition results with normalized ``x y`` and the image size), so the Params
give them: ``fx`` and ``calibrationWidth`` × ``calibrationHeight`` are required by the clustering
plugins (``fy``, ``cx``, ``cy`` default to the ideal pinhole's), and every line input of the
fusion has a ``cameras`` entry or the default camera's Params. Shown on two cameras: the lab's Asus
Xtion (640 × 480) and a wider one of non-square pixels and off-centre principal point (800 × 600).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
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
from plugins.processing.fusion import FeatureFusion
from runtime.kernel.interfaces import ParamError
from runtime.registry import Registry
from runtime.resources.spt import Context
from runtime.verification.verify import verify

CTX = Context(frame=0, stamp=0.0, resource="R")
OTHER = Camera(460.0, 455.0, 412.0, 291.5, 800, 600)
"""Not the lab's camera: wider (83° across), non-square pixels, principal point off the centre, 800 × 600."""
CAMERAS = {"xtion": XTION, "other": OTHER}


def params_of(camera: Camera) -> dict[str, object]:
    return {
        "fx": camera.fx,
        "fy": camera.fy,
        "cx": camera.cx,
        "cy": camera.cy,
        "calibrationWidth": camera.width,
        "calibrationHeight": camera.height,
    }


def record(kind: str, params: Mapping[str, object]) -> Plugin:
    return Plugin(name="p", kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in params.items()))


# --------------------------------------------------------------------------- the plugins use what is given


@pytest.mark.parametrize("name", list(CAMERAS))
def test_the_clustering_places_objects_with_the_camera_it_is_given(name: str) -> None:
    camera, wrong = CAMERAS[name], CAMERAS["other" if name == "xtion" else "xtion"]
    scene = render_depth_scene(seed=2, resolution=(camera.height, camera.width), camera=camera)
    assert all(t.pixels > 1000 for t in scene.truth)
    depth = DepthAcquisition(record("depth-acquisition", {})).process(scene.depth, CTX)
    given = {"tolerance": 0.02, "minPoints": 400}
    plugin = EuclideanClustering(record("euclidean-clustering", given | params_of(camera)))
    assert plugin.camera == camera
    clusters = plugin.process(depth, CTX)
    assert len(clusters) == len(scene.truth)
    for cluster, truth in zip(clusters, scene.truth, strict=True):
        assert math.dist(cluster.centroid, (truth.x, truth.y, truth.z)) < 0.05
    # The other camera's intrinsics on the same frame put the objects elsewhere: the Params are what is used.
    misplaced = EuclideanClustering(record("euclidean-clustering", given | params_of(wrong))).process(depth, CTX)
    worst = max(math.dist(c.centroid, (t.x, t.y, t.z)) for c, t in zip(misplaced, scene.truth, strict=False))
    assert worst > 0.1


def test_fy_cx_cy_default_to_the_pinhole_of_the_given_focal_length_and_size() -> None:
    lab = {"fx": 525, "calibrationWidth": 640, "calibrationHeight": 480}
    assert EuclideanClustering(record("euclidean-clustering", lab)).camera == XTION
    other = {"fx": 460, "calibrationWidth": 800, "calibrationHeight": 600}
    assert EuclideanClustering(record("euclidean-clustering", other)).camera == Camera(460, 460, 399.5, 299.5, 800, 600)


def lone_ray(plugin: FeatureFusion, source: str, camera: Camera, at: tuple[float, float, float]) -> Any:
    """The direction of the lone ray the fusion makes of a line observation of the point ``at``,
    as keypoint-matching reports it: pixel / image size, at a half-size profile of ``camera``."""
    cols, rows = camera.width // 2, camera.height // 2
    fx, fy, cx, cy = camera.intrinsics(rows, cols)
    u, v = fx * at[0] / at[2] + cx, fy * at[1] / at[2] + cy
    seen = {"name": "box_cereal", "x": u / cols, "y": v / rows, "reliability": 0.7}
    (obj,) = plugin.process({source: {"objects": [seen], "width": cols, "height": rows}}, CTX)["objects"]
    return np.array(obj["direction"])


def test_each_line_input_s_ray_uses_its_own_camera() -> None:
    entry = " ".join(f"{v:g}" for v in (OTHER.fx, OTHER.fy, OTHER.cx, OTHER.cy, OTHER.width, OTHER.height))
    given = {"inputs": "rgb: line; other: line; depth: point", "cameras": f"other: {entry}", "objects": ""}
    plugin = FeatureFusion(record("feature-fusion", given | params_of(XTION)))
    assert plugin.cameras == {"rgb": XTION, "other": OTHER}
    at = (0.3, -0.1, 1.5)
    for source, camera in (("rgb", XTION), ("other", OTHER)):
        assert lone_ray(plugin, source, camera, at) == pytest.approx(np.array(at) / np.linalg.norm(at), abs=1e-9)


# --------------------------------------------------------------------------- verify refuses the lack of them

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="intrinsics">
  <Topic name="/depth" type="bytes"/>
  <Topic name="/clusters" type="bytes"/>
  <Node name="pc"/>
  <SmartResource name="R" node="pc">
    <Plugin name="clusters" kind="euclidean-clustering">
      <Param name="tolerance" value="0.02"/>{clusters}
    </Plugin>
    <Plugin name="fusion" kind="feature-fusion">
      <Param name="inputs" value="rgb: line; other: line; depth: point"/>{fusion}
    </Plugin>
    <Profile name="p"><Use plugin="clusters"/></Profile>
    <Service name="S">
      <Input name="depth" topic="/depth"/><Output name="clusters" topic="/clusters"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="p" profile="p"><Policy measure="latency" upper="0.1"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""
RESOURCE = "/System[@name='intrinsics']/SmartResource[@name='R']"
OTHER_ENTRY = "other: 460 455 412 291.5 800 600"
NO_CAMERA = "processing plugin 'feature-fusion': line input {!r} has no intrinsics: give it a 'cameras' entry, or "


def problems(tmp_path: Path, *, clusters: str = "", fusion: str = "") -> list[str]:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.format(clusters=clusters, fusion=fusion), encoding="utf-8")
    return [str(error) for error in verify(ckmconf.load(path), Registry(packages=("ckm",)))]


def params_xml(camera: Camera, names: tuple[str, ...] = ("fx", "calibrationWidth", "calibrationHeight")) -> str:
    return "".join(f'<Param name="{n}" value="{params_of(camera)[n]}"/>' for n in names)


def cameras_xml(entries: str) -> str:
    return f'<Param name="cameras" value="{entries}"/>'


def test_verify_refuses_a_configuration_without_intrinsics_at_its_file_line_column(tmp_path: Path) -> None:
    found = problems(tmp_path, fusion=cameras_xml(OTHER_ENTRY))
    file = tmp_path / "system.xml"
    column = file.read_text().splitlines()[10].index('value="other') + 1  # line 11: the cameras Param's value
    clusters = f"{file}:7:5: {RESOURCE}/Plugin[@name='clusters']: plugin 'clusters' (euclidean-clustering): "
    assert found == [
        f"{clusters}give the camera's intrinsics: Params fx, calibrationWidth and calibrationHeight (missing: fx, "
        "calibrationWidth, calibrationHeight), or camera naming its HWChannel",
        f"{file}:11:{column}: {RESOURCE}/Plugin[@name='fusion']/Param[@name='cameras']/@value: "
        + NO_CAMERA.format("rgb")
        + "parameters 'fx', 'calibrationWidth' and 'calibrationHeight' (the line inputs' default camera)",
    ]
    # The lab's Xtion as the clustering's camera and the fusion's default one, the other camera's entry: accepted.
    fusion = cameras_xml(OTHER_ENTRY) + params_xml(XTION)
    assert problems(tmp_path, clusters=params_xml(XTION), fusion=fusion) == []
    # Each line input its own entry, the other camera (all six Params) for the clustering: accepted.
    both = cameras_xml(f"rgb: 525 525 319.5 239.5 640 480; {OTHER_ENTRY}")
    assert problems(tmp_path, clusters=params_xml(OTHER, tuple(params_of(OTHER))), fusion=both) == []


def test_a_partial_default_camera_is_refused_at_the_plugin_naming_what_is_missing(tmp_path: Path) -> None:
    found = problems(tmp_path, clusters=params_xml(OTHER), fusion='<Param name="fx" value="525"/>')
    where = f"{tmp_path / 'system.xml'}:10:5: {RESOURCE}/Plugin[@name='fusion']: "
    missing = "parameters 'calibrationWidth' and 'calibrationHeight' (the line inputs' default camera)"
    assert found == [where + NO_CAMERA.format("other") + missing, where + NO_CAMERA.format("rgb") + missing]


def test_the_build_refuses_the_same_configuration() -> None:
    """The same manifest builds the plugin: without the Params it is not built (no default camera)."""
    with pytest.raises(ParamError) as caught:
        EuclideanClustering(record("euclidean-clustering", {"fx": 525}))
    assert str(caught.value) == (
        "plugin 'p' (euclidean-clustering): give the camera's intrinsics: Params fx, calibrationWidth and "
        "calibrationHeight (missing: calibrationWidth, calibrationHeight), or camera naming its HWChannel"
    )
    with pytest.raises(ParamError) as caught:
        FeatureFusion(record("feature-fusion", {"inputs": "rgb: line"}))
    assert str(caught.value) == (
        "plugin 'p' (feature-fusion): line input 'rgb' has no intrinsics: give it a 'cameras' entry, or parameters "
        "'fx', 'calibrationWidth' and 'calibrationHeight' (the line inputs' default camera)"
    )
