"""``plugin.tabletop-clustering`` (D117): objects standing on the workbench, seen by the simulated Xtion,
are clusters of their own, on the table top's plane, which the KD-tree classifier recognises."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from benchmarks.fusion import _camera_offset, base_for
from benchmarks.fusion_scene import Lab
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.depth import EuclideanClustering, to_metres
from plugins.processing.image import resize
from plugins.processing.tabletop import TabletopClustering
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

CTX = Context(frame=0, stamp=0.0, resource="RGBDCamera")


@pytest.fixture(scope="module")
def frame() -> Iterator[tuple[Lab, np.ndarray]]:
    """A QVGA depth frame (metres) of the three cylinders, 0.8 m in front of the blue one."""
    lab = Lab("VGA", "QVGA", seed=5)
    x, y, _ = lab.targets["cylinder_blue_dots"].centre
    lab.place(*base_for((x, y - 0.8), math.pi / 2, _camera_offset()))
    _, depth, _ = lab.render()
    yield lab, resize(to_metres(depth, 0.001, "test"), 240, 320, area=False)
    lab.close()


def plugin(cls: type[EuclideanClustering], lab: Lab, **extra: object) -> EuclideanClustering:
    focal = lab.fusion.cameras["rgb"].fx
    camera = {"fx": focal, "fy": focal, "cx": 319.5, "cy": 239.5, "calibrationWidth": 640, "calibrationHeight": 480}
    given = {"tolerance": 0.03, "minPoints": 100} | camera | extra
    kind = "tabletop-clustering" if cls is TabletopClustering else "euclidean-clustering"
    return cls(Plugin(name="c", kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in given.items())))


def which(lab: Lab, centroid: tuple[float, float, float], rotation: np.ndarray, position: np.ndarray) -> str | None:
    """The workbench cylinder a camera-frame centroid lies within 6 cm of (map frame), if any."""
    at = rotation @ np.array(centroid) + position
    for name, target in lab.targets.items():
        if name.startswith("cylinder_") and math.dist(at[:2], target.centre[:2]) < 0.06:
            return name
    return None


def test_the_dominant_plane_alone_leaves_the_objects_on_the_table_top(frame: tuple[Lab, np.ndarray]) -> None:
    lab, depth = frame
    rotation, position = lab.camera_pose()
    plain = plugin(EuclideanClustering, lab).process(depth, CTX)
    assert {which(lab, c.centroid, rotation, position) for c in plain} == {None}
    clusters = [
        c
        for c in plugin(TabletopClustering, lab).process(depth, CTX)
        if which(lab, c.centroid, rotation, position) is not None
    ]
    assert {which(lab, c.centroid, rotation, position) for c in clusters} == {
        "cylinder_red_stripes",
        "cylinder_blue_dots",
        "cylinder_green_checker",
    }
    for cluster in clusters:  # each stands on the workbench top: 0.30 m above the floor
        assert cluster.plane is not None
        assert position[2] - cluster.plane[3] == pytest.approx(0.30, abs=0.015)


def test_the_classifier_names_them_cylinders(frame: tuple[Lab, np.ndarray]) -> None:
    lab, depth = frame
    result = lab.depth[-1].process(plugin(TabletopClustering, lab).process(depth, CTX), CTX)
    rotation, position = lab.camera_pose()
    named = [o["name"] for o in result["objects"] if which(lab, (o["x"], o["y"], o["z"]), rotation, position)]
    assert len(named) >= 3 and set(named) == {"cylinder"}


def test_bad_params_are_refused() -> None:
    camera = (Param(name="fx", value="525"), Param(name="calibrationWidth", value="640"),
              Param(name="calibrationHeight", value="480"))
    with pytest.raises(ParamError, match="parameter 'planes' = 0 must be at least 1"):
        TabletopClustering(
            Plugin(name="c", kind="tabletop-clustering", params=(*camera, Param(name="planes", value="0")))
        )
    with pytest.raises(ParamError, match="parameter 'plane' must stay true"):
        TabletopClustering(
            Plugin(name="c", kind="tabletop-clustering", params=(*camera, Param(name="plane", value="false")))
        )
