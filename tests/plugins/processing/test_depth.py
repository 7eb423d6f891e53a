"""Depth recognition plugins (§7.4.1): acquisition, Euclidean clustering and KD-tree shape classification,
alone and as the RGBDCamera's DEPTH_VGA / DEPTH_QVGA / DEPTH_QQVGA profiles run by the real Smart Plugin
Topology; the synthetic depth renderer, the descriptor model file and its regeneration."""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from ckm_lab.shape_training import generate_model
from ckm_lab.shapes import (
    LAB_SCENE,
    XTION,
    PcdError,
    Shape,
    describe,
    format_pcd,
    read_pcd,
    render_depth_scene,
)

from ckmconf.errors import ConfigError, Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin, SmartResource
from plugins.processing.depth import (
    DepthAcquisition,
    EuclideanClustering,
    KdTreeShapeClassifier,
    ModelError,
    backproject,
    find_support_plane,
)
from plugins.processing.image import resize
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, Topology
from tests.conftest import CONFIGS
from tests.plugins.processing.camera_profiles import camera_with, every_profile

CTX = Context(frame=0, stamp=0.0, resource="RGBDCamera")
RESOURCES = CONFIGS / "usecase" / "resources.xml"
MODEL = CONFIGS / "usecase" / "models" / "lab_objects_shapes.pcd"
PROFILES = ("DEPTH_VGA", "DEPTH_QVGA", "DEPTH_QQVGA")
LAB_NAMES = ["box", "cylinder", "box", "sphere"]  # LAB_SCENE's shapes, left to right
LOC = Loc(str(RESOURCES), 1, 1, "/Part/SmartResource/Plugin")  # models/… resolve next to it
LAB_CAMERA = {"fx": XTION.fx, "calibrationWidth": XTION.width, "calibrationHeight": XTION.height}
"""The intrinsics Params of the camera the synthetic scenes are rendered with (fy, cx, cy: the pinhole's)."""


def plugin(kind: str, params: Mapping[str, object] | None = None, *, name: str = "p", loc: Loc | None = None) -> Plugin:
    given = tuple(Param(name=k, value=str(v)) for k, v in (params or {}).items())
    return Plugin(name=name, kind=kind, params=given, loc=loc)


def metres(depth: Any) -> np.ndarray[Any, Any]:
    result: np.ndarray[Any, Any] = DepthAcquisition(plugin("depth-acquisition")).process(depth, CTX)
    return result


def clustering(**params: object) -> EuclideanClustering:
    return EuclideanClustering(plugin("euclidean-clustering", LAB_CAMERA | params))


def classifier(k: int = 5, threshold: float = 0.75) -> KdTreeShapeClassifier:
    shapes = KdTreeShapeClassifier(
        plugin(
            "kdtree-shape-classifier",
            {"model": "models/lab_objects_shapes.pcd", "k": k, "threshold": threshold},
            loc=LOC,
        )
    )
    shapes.setup()
    return shapes


@pytest.fixture(scope="module")
def lab_vga() -> np.ndarray[Any, Any]:
    return metres(render_depth_scene(seed=0).depth)


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    ("kind", "params", "message"),
    [
        ("depth-acquisition", {"scale": 0}, "parameter 'scale' = 0.0 must be greater than 0"),
        ("depth-acquisition", {"scale": "mm"}, "parameter 'scale' = 'mm' is not a float"),
        ("euclidean-clustering", {"tolerance": -0.02}, "parameter 'tolerance' = -0.02 must be greater than 0"),
        ("euclidean-clustering", {"minPoints": 0}, "parameter 'minPoints' = 0 must be at least 1"),
        ("euclidean-clustering", {"planeAngle": 120}, "parameter 'planeAngle' = 120.0 is not in (0, 90] degrees"),
        ("euclidean-clustering", {"fx": 0}, "parameter 'fx' = 0.0 must be greater than 0"),
        ("kdtree-shape-classifier", {}, "parameter 'model' must name a PCD file"),
        ("kdtree-shape-classifier", {"model": "m.pcd", "k": 0}, "parameter 'k' = 0 must be at least 1"),
        (
            "kdtree-shape-classifier",
            {"model": "m.pcd", "threshold": 1.5},
            "parameter 'threshold' = 1.5 is not in [0, 1]",
        ),
        ("kdtree-shape-classifier", {"model": "m.pcd", "spread": 0}, "parameter 'spread' = 0.0 must be greater than 0"),
    ],
)
def test_bad_params_are_refused(kind: str, params: Mapping[str, object], message: str) -> None:
    cls = {"depth-acquisition": DepthAcquisition, "euclidean-clustering": EuclideanClustering}.get(
        kind, KdTreeShapeClassifier
    )
    given = LAB_CAMERA | dict(params) if kind == "euclidean-clustering" else params
    with pytest.raises(ParamError) as caught:
        cls(plugin(kind, given))
    assert str(caught.value) == f"plugin 'p' ({kind}): {message}"


def test_unknown_param_lists_the_accepted_ones() -> None:
    with pytest.raises(ParamError, match=r"takes no parameter 'eps' \(accepted: calibrationHeight, calibrationWidth"):
        clustering(eps=0.02)


def test_bad_param_in_the_usecase_is_a_config_error_at_its_plugin(depth_camera: SmartResource) -> None:
    index = next(i for i, p in enumerate(depth_camera.plugins) if p.name == "cluster_qvga")
    broken = dataclasses.replace(depth_camera.plugins[index], params=(Param(name="tolerance", value="0"),))
    plugins = (*depth_camera.plugins[:index], broken, *depth_camera.plugins[index + 1 :])
    with pytest.raises(ConfigError) as caught:
        Topology(dataclasses.replace(depth_camera, plugins=plugins))
    assert caught.value.line == depth_camera.plugins[index].loc.line  # type: ignore[union-attr]
    assert str(caught.value).endswith(
        "plugin 'cluster_qvga' (tabletop-clustering): parameter 'tolerance' = 0.0 must be greater than 0"
    )


# --------------------------------------------------------------------------- acquisition


def test_raw_millimetres_become_metres_with_nan_for_no_return() -> None:
    raw = np.array([[0, 1000], [2500, 65535]], dtype=np.uint16)
    depth = metres(raw)
    assert depth.dtype == np.float32 and not depth.flags.writeable
    assert np.isnan(depth[0, 0])
    assert np.allclose(depth[~np.isnan(depth)], [1.0, 2.5, 65.535])
    assert raw[0, 0] == 0 and raw[0, 1] == 1000  # input untouched


def test_float_metres_pass_through_with_invalid_values_as_nan() -> None:
    given = np.array([[1.25, 0.0, -1.0], [np.inf, np.nan, 3.0]], dtype=np.float64)
    depth = metres(given)
    assert depth.dtype == np.float32
    assert depth[0, 0] == 1.25 and depth[1, 2] == 3.0
    assert np.isnan(depth[[0, 0, 1, 1], [1, 2, 0, 1]]).all()
    assert given[0, 1] == 0.0  # input untouched


@pytest.mark.parametrize("bigendian", [False, True])
def test_image_messages_in_16uc1_and_32fc1(bigendian: bool) -> None:
    order = ">" if bigendian else "<"
    raw = np.array([[0, 800, 1200], [1500, 2000, 0]], dtype=f"{order}u2")
    padded = np.zeros((2, 4), dtype=f"{order}u2")
    padded[:, :3] = raw  # rows carry one pixel of padding: step = 8 bytes
    message = {
        "width": 3,
        "height": 2,
        "encoding": "16UC1",
        "data": padded.tobytes(),
        "step": 8,
        "is_bigendian": bigendian,
    }
    depth = metres(message)
    assert np.allclose(np.nan_to_num(depth), [[0, 0.8, 1.2], [1.5, 2.0, 0]])
    floats = np.array([[0.5, np.nan]], dtype=f"{order}f4")
    message = {"width": 2, "height": 1, "encoding": "32FC1", "data": floats.tobytes(), "is_bigendian": bigendian}
    depth = metres(message)
    assert depth[0, 0] == 0.5 and np.isnan(depth[0, 1])


GOOD = {"width": 2, "height": 1, "encoding": "16UC1", "data": b"\x01\x00\x02\x00"}


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"width": 2, "height": 1}, "depth message has no 'encoding', 'data'"),
        ({**GOOD, "encoding": "rgb8"}, "depth encoding 'rgb8' is not one of 16UC1, mono16, 32FC1"),
        ({**GOOD, "width": 0}, "depth message width 0 is not a positive integer"),
        ({**GOOD, "height": "1"}, "depth message height '1' is not a positive integer"),
        ({**GOOD, "data": b"\x01\x00"}, "depth message has 2 bytes of data, expected 1 rows of 4"),
        ({**GOOD, "data": "abcd"}, "depth message data is str, not bytes"),
        ({**GOOD, "step": 2}, "depth message step 2 is shorter than a row of 2 pixels"),
        (np.zeros((4, 4, 3), dtype=np.uint16), "expects a depth image of shape (H, W), got (4, 4, 3)"),
        (np.zeros((4, 4), dtype=np.int32), "expects raw unsigned (16UC1) or float metres (32FC1) depth, got int32"),
        ([[1, 2], [3, 4]], "expects a depth image or message, got list"),
    ],
)
def test_bad_depth_frames_raise_naming_the_plugin(data: Any, message: str) -> None:
    with pytest.raises(ValueError) as caught:
        DepthAcquisition(plugin("depth-acquisition", name="depth_acquire")).process(data, CTX)
    separator = "" if message.startswith("expects") else ":"
    assert str(caught.value) == f"plugin 'depth_acquire' (depth-acquisition){separator} {message}"


# --------------------------------------------------------------------------- renderer and clustering


def test_renderer_gives_millimetres_of_the_floor_and_ground_truth() -> None:
    camera = XTION
    scene = render_depth_scene(LAB_SCENE, seed=3, noise=False, camera=camera)
    assert scene.depth.shape == (480, 640) and scene.depth.dtype == np.uint16
    row = 400  # a floor pixel: depth = elevation / (y/fy·cos(tilt) + sin(tilt))
    floor = camera.elevation / ((row - camera.cy) / camera.fy * math.cos(camera.tilt) + math.sin(camera.tilt))
    assert abs(int(scene.depth[row, 5]) - floor * 1000) <= 0.5
    assert scene.depth[0, 0] == 0  # above the horizon: no return
    assert [t.name for t in scene.truth] == ["box_cereal", "cylinder", "box_orange", "ball"]
    assert all(t.pixels > 1000 for t in scene.truth)
    assert np.array_equal(render_depth_scene(seed=3).depth, render_depth_scene(seed=3).depth)
    assert not np.array_equal(render_depth_scene(seed=3).depth, render_depth_scene(seed=4).depth)
    hidden = render_depth_scene([Shape("sphere", 0.0, -1.0, (0.05,))], resolution=(120, 160))
    assert hidden.truth[0].pixels == 0  # behind the camera


def test_support_plane_is_the_floor() -> None:
    camera = dataclasses.replace(XTION, elevation=0.6, tilt=0.3)
    depth = metres(render_depth_scene(seed=1, camera=camera).depth)
    plane = find_support_plane(backproject(depth, camera, 3.5), distance=0.015, max_angle=math.radians(45))
    assert plane is not None
    assert np.allclose(plane[:3], (0.0, -math.cos(0.3), -math.sin(0.3)), atol=0.01)
    assert plane[3] == pytest.approx(0.6, abs=0.01)


def test_clusters_are_the_objects_left_to_right(lab_vga: np.ndarray[Any, Any]) -> None:
    truth = render_depth_scene(seed=0).truth
    clusters = clustering(tolerance=0.02, minPoints=400).process(lab_vga, CTX)
    assert len(clusters) == 4
    for cluster, seen in zip(clusters, truth, strict=True):
        assert math.dist(cluster.centroid, (seen.x, seen.y, seen.z)) < 0.05
        assert 0.8 * seen.pixels < cluster.count <= seen.pixels  # the bottom 1.5 cm go with the floor
        assert not cluster.points.flags.writeable and cluster.plane is not None
        assert max(cluster.extent) < 0.2


def test_two_close_objects_are_separated_and_small_ones_dropped() -> None:
    scene = render_depth_scene(
        [
            Shape("box", -0.05, 1.0, (0.06, 0.06, 0.12)),
            Shape("box", 0.05, 1.0, (0.06, 0.06, 0.12)),  # a 4 cm gap
            Shape("sphere", 0.3, 1.0, (0.015,)),  # a marble
        ]
    )
    marble = scene.truth[2].pixels
    assert 50 < marble < 300
    depth = metres(scene.depth)
    assert [c.count > 1000 for c in clustering(tolerance=0.02, minPoints=50).process(depth, CTX)] == [True, True, False]
    assert len(clustering(tolerance=0.02, minPoints=400).process(depth, CTX)) == 2
    assert len(clustering(tolerance=0.06, minPoints=400).process(depth, CTX)) == 1  # the gap is under tolerance


def test_intrinsics_follow_the_image_size(lab_vga: np.ndarray[Any, Any]) -> None:
    vga = clustering(tolerance=0.02, minPoints=400).process(lab_vga, CTX)
    qqvga = clustering(tolerance=0.04, minPoints=25).process(resize(lab_vga, 120, 160, area=False), CTX)
    assert len(vga) == len(qqvga) == 4
    for big, small in zip(vga, qqvga, strict=True):
        assert math.dist(big.centroid, small.centroid) < 0.01


def test_floor_only_gives_no_cluster_unless_the_plane_is_kept() -> None:
    floor = metres(render_depth_scene([], resolution=(240, 320)).depth)
    assert clustering(tolerance=0.03).process(floor, CTX) == []
    kept = clustering(tolerance=0.03, plane="false").process(floor, CTX)
    assert max(c.count for c in kept) > 10_000


def test_clustering_wants_metres() -> None:
    with pytest.raises(ValueError, match=r"^plugin 'p' \(euclidean-clustering\) expects a float depth image in metres"):
        clustering().process(np.zeros((4, 4), dtype=np.uint16), CTX)


# --------------------------------------------------------------------------- classification


@pytest.mark.parametrize(("rows", "cols", "tolerance", "min_points"), [(480, 640, 0.02, 400), (240, 320, 0.03, 100)])
def test_lab_objects_are_recognized(
    lab_vga: np.ndarray[Any, Any], rows: int, cols: int, tolerance: float, min_points: int
) -> None:
    clusters = clustering(tolerance=tolerance, minPoints=min_points).process(
        resize(lab_vga, rows, cols, area=False), CTX
    )
    result = classifier(k=5, threshold=0.8).process(clusters, CTX)
    assert [o["name"] for o in result["objects"]] == LAB_NAMES
    assert all(o["reliability"] >= 0.8 for o in result["objects"])
    for found, seen in zip(result["objects"], render_depth_scene(seed=0).truth, strict=True):
        assert math.dist((found["x"], found["y"], found["z"]), (seen.x, seen.y, seen.z)) < 0.05
    assert result["reliability"] == pytest.approx(np.mean([o["reliability"] for o in result["objects"]]))
    assert msgpack.unpackb(msgpack.packb(result)) == result


def test_an_unlearned_shape_is_unknown_and_left_out_of_the_reliability() -> None:
    scene = render_depth_scene([Shape("box", -0.2, 1.6, (0.4, 0.3, 0.5)), Shape("cylinder", 0.25, 1.2, (0.035, 0.12))])
    clusters = clustering(tolerance=0.02, minPoints=400).process(metres(scene.depth), CTX)
    result = classifier().process(clusters, CTX)
    crate, can = result["objects"]
    assert crate["name"] == "unknown" and crate["reliability"] < 0.1
    assert can["name"] == "cylinder"
    assert result["reliability"] == can["reliability"]


def test_nothing_seen_means_no_object_and_zero_reliability() -> None:
    assert classifier().process([], CTX) == {"objects": [], "reliability": 0.0}
    with pytest.raises(ValueError, match="expects the clusters of a euclidean-clustering plugin"):
        classifier().process([np.zeros((5, 3))], CTX)


@pytest.mark.parametrize("count", [1, 2, 3, 7])
def test_descriptor_of_a_tiny_cluster_is_finite(count: int) -> None:
    points = np.random.default_rng(count).normal([0.0, 0.0, 1.0], 0.01, (count, 3)).astype(np.float32)
    assert np.isfinite(describe(points, (0.0, -1.0, 0.0, 0.05))).all()
    assert np.isfinite(describe(points, None)).all()


def test_model_path_is_relative_to_the_declaring_file_or_the_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "models").mkdir()
    shutil.copy(MODEL, tmp_path / "models" / "shapes.pcd")
    loc = Loc(str(tmp_path / "resources.xml"), 3, 5, "/Part/SmartResource/Plugin")
    declared = KdTreeShapeClassifier(plugin("kdtree-shape-classifier", {"model": "models/shapes.pcd"}, loc=loc))
    assert declared.path == tmp_path / "models" / "shapes.pcd"
    declared.setup()
    monkeypatch.chdir(tmp_path)
    loose = KdTreeShapeClassifier(plugin("kdtree-shape-classifier", {"model": "models/shapes.pcd"}))
    loose.setup()
    assert loose.model is not None and len(loose.model.labels) == len(read_pcd(MODEL).labels)


def test_missing_or_malformed_model_is_a_clear_error_at_setup(tmp_path: Path) -> None:
    loc = Loc(str(tmp_path / "resources.xml"), 3, 5, "/Part/SmartResource/Plugin")
    shapes = KdTreeShapeClassifier(plugin("kdtree-shape-classifier", {"model": "none.pcd"}, name="shape_vga", loc=loc))
    with pytest.raises(RuntimeError, match="setup"):
        shapes.process([], CTX)
    with pytest.raises(ModelError) as caught:
        shapes.setup()
    assert str(caught.value) == (
        f"plugin 'shape_vga' (kdtree-shape-classifier): cannot read model file {tmp_path / 'none.pcd'}: "
        "No such file or directory"
    )
    (tmp_path / "none.pcd").write_text(MODEL.read_text().replace("DATA ascii", "DATA binary"))
    with pytest.raises(ModelError) as caught:
        shapes.setup()
    assert str(caught.value) == (
        f"plugin 'shape_vga' (kdtree-shape-classifier): bad model file {tmp_path / 'none.pcd'}:14: "
        "DATA 'binary' is not supported (only ascii)"
    )


# --------------------------------------------------------------------------- the model file


def _edit(lines: list[str], number: int, text: str | None) -> list[str]:
    """Line ``number`` (1-based) replaced by ``text``, or removed when None."""
    return [*lines[: number - 1], *([] if text is None else [text]), *lines[number:]]


@pytest.mark.parametrize(
    ("number", "text", "line", "message"),
    [
        (5, "VERSION 0.6", 5, "unsupported VERSION '0.6' (expected 0.7)"),
        (5, "FIELDS x y z", 5, "expected VERSION, found 'FIELDS'"),
        (
            6,
            "FIELDS height width depth label",
            6,
            "FIELDS 'height width depth label' are not the descriptor's "
            "(height width depth top_ratio hinge_residual circle_residual curvature label)",
        ),
        (7, "SIZE 4 4", 7, "SIZE has 2 entries for 8 fields"),
        (8, "TYPE F F F F F F F F", 8, "TYPE must be F for the descriptor fields and U or I for the label"),
        (9, "COUNT 1 1 1 1 1 1 3 1", 9, "every COUNT must be 1"),
        (10, "WIDTH -3", 10, "WIDTH must be a non-negative integer"),
        (10, "WIDTH 3", 14, "WIDTH × HEIGHT is not POINTS (701)"),
        (14, "DATA binary_compressed", 14, "DATA 'binary_compressed' is not supported (only ascii)"),
        (2, "# labels: 0=box 0=cube", 2, "label 0 is named twice"),
        (2, "# labels: box cylinder", 2, "bad label 'box' in '# labels:' (expected INDEX=NAME)"),
        (2, None, 13, "no '# labels: 0=name …' comment before DATA"),
        (15, "1 2 3 4 5 6 7", 15, "7 values for 8 fields"),
        (15, "1 2 3 4 5 6 __import__('os') 0", 15, "not a number in \"1 2 3 4 5 6 __import__('os') 0\""),
        (16, "1 2 3 4 5 6 nan 0", 16, "a value is not finite"),
        (17, "1 2 3 4 5 6 7 9", 17, "label 9 is not in '# labels:' (0, 1, 2)"),
        (715, None, 714, "700 data rows for POINTS 701"),
    ],
)
def test_pcd_parser_rejects_malformed_files_with_path_and_line(
    tmp_path: Path, number: int, text: str | None, line: int, message: str
) -> None:
    path = tmp_path / "bad.pcd"
    path.write_text("\n".join(_edit(MODEL.read_text().splitlines(), number, text)) + "\n")
    with pytest.raises(PcdError) as caught:
        read_pcd(path)
    assert str(caught.value) == f"{path}:{line}: {message}"


def test_pcd_parser_refuses_empty_and_binary_files(tmp_path: Path) -> None:
    empty = tmp_path / "empty.pcd"
    empty.write_text("# nothing\n")
    with pytest.raises(PcdError, match=r"empty.pcd:1: no PCD header$"):
        read_pcd(empty)
    junk = tmp_path / "junk.pcd"
    junk.write_bytes(b"VERSION 0.7\n\xff\xfe")
    with pytest.raises(PcdError, match=r"junk.pcd:0: not an ASCII file$"):
        read_pcd(junk)


def test_committed_model_is_a_small_pcd_that_the_generator_reproduces() -> None:
    text = MODEL.read_text()
    assert len(text.encode()) < 100_000
    committed = read_pcd(MODEL)
    assert dict(committed.names) == {0: "box", 1: "cylinder", 2: "sphere"}
    assert np.bincount(committed.labels).min() > 200  # every shape well represented
    notes = [line[2:] for line in text.splitlines()[2:4]]
    assert format_pcd(committed, notes) == text  # the file is exactly what format_pcd writes
    regenerated = generate_model()
    assert np.array_equal(regenerated.labels, committed.labels)
    assert np.allclose(regenerated.descriptors, committed.descriptors, atol=2e-3)  # float noise across machines


# --------------------------------------------------------------------------- the use case's profiles


@pytest.fixture(scope="module")
def depth_camera() -> SmartResource:
    """The use case's RGBDCamera (from lab.xml) with only the depth plugins and profiles."""
    return camera_with(CONFIGS / "usecase" / "lab.xml", PROFILES)


@pytest.fixture(scope="module")
def topology(depth_camera: SmartResource) -> Iterator[Topology]:
    with every_profile(depth_camera, PROFILES) as spt:
        yield spt


def test_depth_profiles_run_through_the_topology(topology: Topology) -> None:
    topology.reset_stats()
    simulated = dataclasses.replace(XTION, fx=577.3, fy=577.3)  # the simulated Xtion resources.xml names
    scene = render_depth_scene(seed=0, camera=simulated)
    frame = topology.run({"width": 640, "height": 480, "encoding": "16UC1", "data": scene.depth.tobytes()})
    assert set(frame.outputs) == set(PROFILES)
    for profile in PROFILES:
        result = frame.outputs[profile]
        assert [o["name"] for o in result["objects"]] == LAB_NAMES, profile
        assert 0.8 < result["reliability"] <= 1.0
        assert msgpack.unpackb(msgpack.packb(result)) == result
    stats = topology.stats()
    assert stats["depth_acquire"].calls == 1  # the shared root runs once for the three profiles
    assert all(stats[name].calls == 1 for name in ("cluster_vga", "shape_qvga", "shape_qqvga"))


def test_qqvga_still_finds_every_object_but_trusts_the_boxes_less(topology: Topology) -> None:
    """At 160×120 a lab box is about 9 pixels wide: the objects are all found, but the box votes
    are less unanimous than at VGA (what the TCM trades against CPU and deadline)."""
    frame = topology.run(render_depth_scene(seed=0).depth)
    vga, qqvga = frame.outputs["DEPTH_VGA"]["objects"], frame.outputs["DEPTH_QQVGA"]["objects"]
    assert [o["name"] for o in qqvga] == LAB_NAMES
    assert all(small["points"] < big["points"] / 10 for big, small in zip(vga, qqvga, strict=True))
    assert all(o["reliability"] >= 0.7 for o in qqvga)


def test_a_use_case_depth_image_message_is_read_as_raw_depths() -> None:
    """The simulated Xtion's DepthImage (configs/usecase/network.xml): width, height and the raw depths
    as an array, no encoding (what the sensor publishes, D99)."""
    raw = np.array([0, 1000, 2500, 65535], dtype=np.uint16)
    message = {"stamp": 1.0, "width": 2, "height": 2, "scale": 0.001, "data": raw}
    metres = DepthAcquisition(plugin("depth-acquisition")).process(message, CTX)
    assert metres.shape == (2, 2) and metres[0, 1] == pytest.approx(1.0) and metres[1, 0] == pytest.approx(2.5)
    with pytest.raises(ValueError, match=r"data \(uint16, 3 values\) is not 2 x 2 depths"):
        DepthAcquisition(plugin("depth-acquisition")).process({**message, "data": raw[:3]}, CTX)


def test_a_recognised_cylinder_is_placed_at_its_axis_not_its_visible_surface(lab_vga: np.ndarray[Any, Any]) -> None:
    clusters = clustering(tolerance=0.02, minPoints=400).process(lab_vga, CTX)
    result = classifier(k=5, threshold=0.8).process(clusters, CTX)
    truth = render_depth_scene(seed=0).truth
    cylinders = [(o, seen, c) for o, seen, c in zip(result["objects"], truth, clusters, strict=True)
                 if o["name"] == "cylinder"]
    assert cylinders

    def across_the_table(a: Any, b: Any, normal: np.ndarray[Any, Any]) -> float:
        """How far apart ``a`` and ``b`` are seen from above the support plane (what a grasp needs)."""
        d = np.subtract(a, b)
        return float(np.linalg.norm(d - (d @ normal) * normal))

    for found, seen, cluster in cylinders:
        assert cluster.plane is not None
        normal = np.asarray(cluster.plane[:3]) / np.linalg.norm(cluster.plane[:3])
        where = (seen.x, seen.y, seen.z)
        surface = across_the_table(cluster.centroid, where, normal)
        axis = across_the_table((found["x"], found["y"], found["z"]), where, normal)
        assert surface > 0.02 and axis < 0.01  # the fitted axis, not the near side's centroid
