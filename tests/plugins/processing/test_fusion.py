"""Feature fusion of the GlobalRecog.Fusion service (§6.3, Algorithm 4, eq. 6.31–6.41, Fig. 7.17):
hand-made observations of known geometry, the C(θ') loop, reliability reinforcement, poses and
triangulation, hostile inputs and Params, the environment catalog, and the real depth pipeline.
Fig. 7.18 from rendered scenes: test_fusion_fig718.py; the map frame: test_fusion_map.py."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
from ckm_lab.shapes import render_depth_scene

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.depth import DepthAcquisition, EuclideanClustering, KdTreeShapeClassifier
from plugins.processing.fusion import FeatureFusion, reinforce, share_at_bound
from plugins.processing.geometry import IDENTITY, Point, Pose, Ray, distance, estimate
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from tests.conftest import CONFIGS

CTX = Context(frame=0, stamp=0.0, resource="GlobalRecog")
LOC = Loc(str(CONFIGS / "usecase" / "resources.xml"), 1, 1, "/Part/SmartResource/Plugin")
CATALOG = "cylinder_red_stripes: cylinder red_stripes; cylinder_blue_dots: cylinder blue_dots; box_cereal: box"
OWNER = "plugin 'f' (feature-fusion)"
LAB_INPUTS = "rgb: line; depth: point; pantilt: line"
"""The lab's three recognition inputs (resources.xml GlobalRecog.Fusion)."""
LAB_CAMERA = {"fx": 525, "calibrationWidth": 640, "calibrationHeight": 480}
"""The line inputs' default camera these tests project with (the lab's Xtion: fy, cx, cy the pinhole's)."""


def fusion(params: Mapping[str, object] | None = None, *, loc: Loc | None = None) -> FeatureFusion:
    given = {"inputs": LAB_INPUTS, "objects": CATALOG, **LAB_CAMERA, **(params or {})}
    record = Plugin(
        name="f", kind="feature-fusion", params=tuple(Param(name=k, value=str(v)) for k, v in given.items())
    )
    if loc is not None:
        record = Plugin(name="f", kind="feature-fusion", params=record.params, loc=loc)
    return FeatureFusion(record)


def seen(name: str, at: tuple[float, float, float], r: float, pose: Pose = IDENTITY) -> dict[str, Any]:
    """An RGB recognition object (keypoint-matching's fields) whose centre projects from ``at``."""
    x, y, z = pose.rotation.T @ (np.array(at) - pose.translation)
    u, v = 525.0 * x / z + 319.5, 525.0 * y / z + 239.5
    return {"name": name, "matches": 40, "inliers": 30, "x": u / 640, "y": v / 480, "reliability": r}


def rgb(*objects: dict[str, Any]) -> dict[str, Any]:
    mean = sum(o["reliability"] for o in objects) / len(objects) if objects else 0.0
    return {"objects": list(objects), "reliability": mean, "keypoints": 500, "width": 640, "height": 480}


def depth(*objects: tuple[str, tuple[float, float, float], float]) -> dict[str, Any]:
    """A depth recognition result (kdtree-shape-classifier's fields) of (shape, centroid, reliability)."""
    found = [{"name": n, "reliability": r, "x": p[0], "y": p[1], "z": p[2], "points": 400} for n, p, r in objects]
    return {"objects": found, "reliability": float(np.mean([r for *_, r in objects])) if objects else 0.0}


def position(obj: Mapping[str, Any]) -> np.ndarray[Any, Any]:
    return np.array([obj["x"], obj["y"], obj["z"]])


RED = (0.1, 0.05, 1.2)


# --------------------------------------------------------------------------- matching and fusion


def test_a_line_and_a_point_of_one_object_fuse_with_higher_reliability() -> None:
    out = fusion().process(
        {
            "rgb": rgb(seen("cylinder_red_stripes", RED, 0.65)),
            "depth": depth(("cylinder", (0.1, 0.05, 1.17), 0.8)),
            "pantilt": None,
        },
        CTX,
    )
    (obj,) = out["objects"]
    assert (obj["name"], obj["shape"], obj["texture"]) == ("cylinder_red_stripes", "cylinder", "red_stripes")
    assert obj["sources"] == ["depth", "rgb"] and obj["observations"] == 2
    assert obj["reliability"] > 0.8 and obj["reinforcement"] > obj["reliability"] - 1e-12
    assert math.dist(position(obj), (0.1, 0.05, 1.17)) < 0.01  # the depth point, pulled onto the line
    assert obj["sigma"] < 0.03 and obj["origin"] is None and obj["direction"] is None
    assert out["reliability"] == obj["reliability"]


def test_a_fused_object_keeps_the_centre_its_point_source_gave() -> None:
    """D253: a ray through the print aside of the axis pulls θ̂ off; ``centre`` is the depth point as given."""
    aside = (RED[0] + 0.03, RED[1], RED[2])  # the print's keypoints, 3 cm aside of the solid's centre
    out = fusion().process(
        {"rgb": rgb(seen("cylinder_red_stripes", aside, 0.65)), "depth": depth(("cylinder", RED, 0.8))}, CTX
    )
    (obj,) = out["objects"]
    assert obj["sources"] == ["depth", "rgb"]
    assert obj["centre"] == pytest.approx(list(RED))
    assert math.dist(position(obj), obj["centre"]) > 0.01  # the fused point leans towards the ray
    (alone,) = fusion().process({"rgb": rgb(seen("cylinder_red_stripes", RED, 0.65))}, CTX)["objects"]
    assert alone["centre"] is None  # a lone ray has no centre


def test_reinforcement_of_a_new_magnitude_is_eq_6_41() -> None:
    """x₁ is the depth point; the RGB line adds a magnitude: r̂ = r₁ + 1/(1 + d(line, θ̂')), θ̂' = x₁."""
    off = np.array([0.1, 0.05 + 0.024, 1.2])  # 2.4 cm below the ray through RED
    out = fusion().process(
        {"rgb": rgb(seen("cylinder_red_stripes", RED, 0.3)), "depth": depth(("cylinder", tuple(off), 0.4))}, CTX
    )
    (obj,) = out["objects"]
    u = np.array(RED) / np.linalg.norm(RED)
    t = float(off @ u)
    d = float(np.linalg.norm(off - t * u)) / math.hypot(0.03, 0.01 * t)  # across the ray, over σ_point ⊕ σ_line·t
    support = 1 / (1 + d)
    assert obj["reinforcement"] == pytest.approx(0.4 + support, rel=1e-9)  # eq. 6.41 literally
    assert obj["reliability"] == pytest.approx(0.4 + support * (1 - 0.4), rel=1e-9)  # its bounded sum (D74)


def test_reinforcement_of_a_known_magnitude_measures_to_x1() -> None:
    """Three point sensors: the third is 1.41 σ from x₁ (eq. 6.41, first case), 2.45 σ from θ̂'."""
    plugin = fusion({"inputs": "a: point; b: point; c: point"})
    data = {
        "a": depth(("box", (0, 0, 1), 0.9)),
        "b": depth(("box", (0.06, 0, 1), 0.8)),
        "c": depth(("box", (-0.06, 0, 1), 0.7)),
    }
    (obj,) = plugin.process(data, CTX)["objects"]
    assert obj["sources"] == ["a", "b", "c"]
    support = 1 / (1 + 0.06 / math.hypot(0.03, 0.03))
    assert obj["reinforcement"] == pytest.approx(0.9 + 2 * support)
    assert obj["reliability"] == pytest.approx(1 - 0.1 * (1 - support) ** 2)  # two probabilistic sums
    assert obj["x"] == pytest.approx(0.0) and obj["sigma"] == pytest.approx(0.03 / math.sqrt(3))


def test_two_instances_of_one_model_stay_two_objects() -> None:
    blue = (0.45, 0.05, 1.25)
    data = {
        "rgb": rgb(seen("cylinder_blue_dots", blue, 0.7), seen("cylinder_red_stripes", RED, 0.6)),
        "depth": depth(("cylinder", RED, 0.9), ("cylinder", blue, 0.5)),
    }
    objects = {o["name"]: o for o in fusion().process(data, CTX)["objects"]}
    assert set(objects) == {"cylinder_red_stripes", "cylinder_blue_dots"}
    assert math.dist(position(objects["cylinder_red_stripes"]), RED) < 0.01
    assert math.dist(position(objects["cylinder_blue_dots"]), blue) < 0.01
    assert all(o["observations"] == 2 for o in objects.values())


def test_two_depth_instances_without_texture_keep_the_shape_name() -> None:
    out = fusion().process({"depth": depth(("box", (0, 0, 1), 0.9), ("box", (0.3, 0, 1), 0.7))}, CTX)
    assert [(o["name"], o["shape"], o["texture"], o["x"]) for o in out["objects"]] == [
        ("box", "box", None, 0.0),
        ("box", "box", None, 0.3),
    ]
    assert out["reliability"] == pytest.approx(0.8)


def test_a_point_off_the_line_is_not_matched() -> None:
    out = fusion().process(
        {"rgb": rgb(seen("cylinder_red_stripes", RED, 0.7)), "depth": depth(("cylinder", (0.3, 0.05, 1.2), 0.9))}, CTX
    )
    line, point = sorted(out["objects"], key=lambda o: o["sources"])[::-1]
    assert line["sources"] == ["rgb"] and point["sources"] == ["depth"]
    assert line["x"] is None and line["sigma"] is None and line["origin"] == [0.0, 0.0, 0.0]
    assert np.allclose(line["direction"], np.array(RED) / np.linalg.norm(RED))
    assert point["name"] == "cylinder" and point["texture"] is None


def test_a_point_behind_the_camera_is_not_on_its_ray() -> None:
    behind = (-RED[0], -RED[1], -RED[2])  # on the ray's line, but behind the camera
    out = fusion().process(
        {"rgb": rgb(seen("cylinder_red_stripes", RED, 0.7)), "depth": depth(("cylinder", behind, 0.9))}, CTX
    )
    assert len(out["objects"]) == 2


def test_other_feature_models_are_never_fused() -> None:
    out = fusion().process({"rgb": rgb(seen("box_cereal", RED, 0.7)), "depth": depth(("cylinder", RED, 0.9))}, CTX)
    assert sorted(o["name"] for o in out["objects"]) == ["box_cereal", "cylinder"]


def test_an_input_observes_an_instance_once() -> None:
    """Red and blue lines through one cylinder: the more reliable joins, the other is its own object."""
    data = {
        "rgb": rgb(seen("cylinder_red_stripes", RED, 0.7), seen("cylinder_blue_dots", RED, 0.6)),
        "depth": depth(("cylinder", RED, 0.9)),
    }
    objects = fusion().process(data, CTX)["objects"]
    assert [(o["name"], o["sources"]) for o in objects] == [
        ("cylinder_red_stripes", ["depth", "rgb"]),
        ("cylinder_blue_dots", ["rgb"]),
    ]


def test_unknown_and_unreliable_objects_are_left_out() -> None:
    data = {"depth": depth(("unknown", (0, 0, 1), 0.5), ("box", (0.3, 0, 1), 0.2), ("box", (0.6, 0, 1), 0.6))}
    out = fusion({"minReliability": 0.3}).process(data, CTX)
    assert [o["x"] for o in out["objects"]] == [0.6]


def test_unmapped_names_are_their_own_model() -> None:
    out = fusion({"objects": ""}).process(
        {"rgb": rgb(seen("cylinder_red_stripes", RED, 0.7)), "depth": depth(("cylinder", RED, 0.9))}, CTX
    )
    assert sorted((o["name"], o["shape"]) for o in out["objects"]) == [
        ("cylinder", "cylinder"),
        ("cylinder_red_stripes", None),
    ]


@pytest.mark.parametrize("data", [{}, {"rgb": None, "depth": None, "pantilt": None}, {"rgb": rgb(), "depth": depth()}])
def test_missing_and_empty_inputs_give_no_objects(data: dict[str, Any]) -> None:
    assert fusion().process(data, CTX) == {"objects": [], "reliability": 0.0}


def test_the_result_is_msgpack_able() -> None:
    out = fusion().process(
        {
            "rgb": rgb(seen("cylinder_red_stripes", RED, 0.7), seen("box_cereal", (-0.3, 0, 1), 0.6)),
            "depth": depth(("cylinder", RED, 0.9)),
        },
        CTX,
    )
    assert msgpack.unpackb(msgpack.packb(out)) == out


def test_reinforcement_stays_a_share_and_grows_with_every_match() -> None:
    assert reinforce(0.6, 0.5) == pytest.approx(0.8)
    assert reinforce(0.0, 0.3) == pytest.approx(0.3) and reinforce(1.0, 0.3) == 1.0
    r = 0.5
    for support in (0.9, 0.9, 0.9, 0.9):
        grown = reinforce(r, support)
        assert r < grown < 1.0
        r = grown


def test_share_at_bound_counts_the_saturated_values() -> None:
    assert share_at_bound([1.0, 0.5, 1.0 - 1e-12, 0.99]) == 0.5
    assert share_at_bound([]) == 0.0
    assert share_at_bound([0.8, 0.9], bound=0.9) == 0.5


# --------------------------------------------------------------------------- max sensors (Table 7.1)


def three_lines_and_a_point() -> dict[str, Any]:
    side = (0.9, 0.05, 1.2, 0.0, -math.pi / 2, 0.0)
    return {
        "rgb": rgb(seen("cylinder_red_stripes", RED, 0.6)),
        "depth": depth(("cylinder", RED, 0.9)),
        "pantilt": rgb(seen("cylinder_red_stripes", RED, 0.7, Pose.from_xyzrpy(*side))),
    }


def test_max_sensors_caps_the_observations_of_one_object() -> None:
    """The most reliable observations are fused; the one beyond the cap is the same instance, so
    it is left out, not reported as another object."""
    poses = "pantilt: 0.9 0.05 1.2 0 -1.5707963267948966 0"
    everything = fusion({"poses": poses}).process(three_lines_and_a_point(), CTX)["objects"]
    assert [o["sources"] for o in everything] == [["depth", "pantilt", "rgb"]]
    capped = fusion({"poses": poses, "maxSensors": 2}).process(three_lines_and_a_point(), CTX)["objects"]
    assert [o["sources"] for o in capped] == [["depth", "pantilt"]]
    assert capped[0]["reliability"] < everything[0]["reliability"]
    alone = fusion({"poses": poses, "maxSensors": 1}).process(three_lines_and_a_point(), CTX)["objects"]
    assert [(o["sources"], o["reliability"]) for o in alone] == [(["depth"], 0.9)]


def test_the_service_parameter_max_sensors_sets_the_cap_at_run_time() -> None:
    plugin = fusion({"poses": "pantilt: 0.9 0.05 1.2 0 -1.5707963267948966 0"})
    plugin.apply_service_parameters({"max_sensors": 2, "other": "ignored"})
    assert plugin.max_sensors == 2
    (obj,) = plugin.process(three_lines_and_a_point(), CTX)["objects"]
    assert obj["observations"] == 2
    plugin.apply_service_parameters({"max_sensors": 3})
    assert plugin.process(three_lines_and_a_point(), CTX)["objects"][0]["observations"] == 3
    for bad in (0, 2.5, "3", True):
        with pytest.raises(ParamError, match=f"service parameter 'max_sensors' = {bad!r} must be a whole number"):
            plugin.apply_service_parameters({"max_sensors": bad})
    assert plugin.max_sensors == 3


def test_the_cap_holds_per_object_not_per_frame() -> None:
    """Two cylinders, each seen by both inputs: with maxSensors 2 each keeps both of its observations."""
    blue = (0.45, 0.05, 1.25)
    data = {
        "rgb": rgb(seen("cylinder_blue_dots", blue, 0.7), seen("cylinder_red_stripes", RED, 0.6)),
        "depth": depth(("cylinder", blue, 0.8), ("cylinder", RED, 0.9)),
    }
    objects = fusion({"maxSensors": 2}).process(data, CTX)["objects"]
    assert sorted((o["name"], o["observations"]) for o in objects) == [
        ("cylinder_blue_dots", 2),
        ("cylinder_red_stripes", 2),
    ]


# --------------------------------------------------------------------------- poses, cameras, geometry


def test_a_second_camera_line_triangulates_and_joins() -> None:
    """The Pan-Tilt camera looks at the object from the side (pose: at x = 0.9, optical axis along −x)."""
    side = Pose.from_xyzrpy(0.9, 0.05, 1.2, 0.0, -math.pi / 2, 0.0)
    plugin = fusion({"poses": "pantilt: 0.9 0.05 1.2 0 -1.5707963267948966 0"})
    alone = plugin.process(
        {
            "rgb": rgb(seen("cylinder_red_stripes", RED, 0.7)),
            "pantilt": rgb(seen("cylinder_red_stripes", RED, 0.6, side)),
        },
        CTX,
    )
    (obj,) = alone["objects"]
    assert obj["sources"] == ["rgb", "pantilt"] and math.dist(position(obj), RED) < 1e-6
    data = {
        "rgb": rgb(seen("cylinder_red_stripes", RED, 0.7)),
        "pantilt": rgb(seen("cylinder_red_stripes", RED, 0.6, side)),
        "depth": depth(("cylinder", (0.1, 0.06, 1.19), 0.9)),
    }
    (obj,) = plugin.process(data, CTX)["objects"]
    assert obj["sources"] == ["depth", "rgb", "pantilt"] and math.dist(position(obj), RED) < 0.01


def test_normalized_coordinates_give_the_same_ray_at_any_resolution() -> None:
    plugin = fusion()
    vga = plugin.process({"rgb": rgb(seen("box_cereal", RED, 0.7))}, CTX)["objects"][0]["direction"]
    qqvga = rgb(seen("box_cereal", RED, 0.7)) | {"width": 160, "height": 120}
    obj = qqvga["objects"][0]
    obj["x"], obj["y"] = (obj["x"] * 640 + 0.5) / 4 / 160 - 0.5 / 160, (obj["y"] * 480 + 0.5) / 4 / 120 - 0.5 / 120
    assert np.allclose(plugin.process({"rgb": qqvga}, CTX)["objects"][0]["direction"], vga)


def test_point_sensor_poses_move_points_into_the_common_frame() -> None:
    plugin = fusion({"poses": "depth: 0.025 0 0 0 0 0"})  # the Xtion's depth sensor, 2.5 cm to the right
    (obj,) = plugin.process({"depth": depth(("box", (0.0, 0.0, 1.0), 0.9))}, CTX)["objects"]
    assert position(obj) == pytest.approx((0.025, 0.0, 1.0))
    plugin.poses["depth"] = IDENTITY  # the hook live poses use
    assert plugin.process({"depth": depth(("box", (0.0, 0.0, 1.0), 0.9))}, CTX)["objects"][0]["x"] == 0.0


def test_geometry_distances_and_estimate() -> None:
    a, b = Point(np.zeros(3), 0.01 * np.eye(3)), Point(np.array([0.3, 0, 0]), 0.08 * np.eye(3))
    assert distance(a, b) == pytest.approx(1.0)
    z = np.array([0.0, 0.0, 1.0])
    ray, parallel = Ray(np.zeros(3), z, 0.01, 0.3), Ray(np.array([0.05, 0, 0]), z, 0.01, 0.3)
    assert distance(ray, Point(np.array([0.0, 0.0, 2.0]), 1e-6 * np.eye(3))) == pytest.approx(0.0)
    assert estimate([ray, parallel]) is ray  # one viewpoint: the range stays unknown
    fused = estimate([a, b])
    assert isinstance(fused, Point) and fused.mean[0] == pytest.approx(0.3 * 0.01 / 0.09)


# --------------------------------------------------------------------------- hostile inputs


MALFORMED = [
    ({"lidar": depth()}, "input 'lidar' is not declared in parameter 'inputs'"),
    ({"rgb": "objects"}, "input 'rgb' field 'objects' is missing or not a list"),
    ({"depth": {"objects": 3}}, "input 'depth' field 'objects' is missing or not a list"),
    ({"rgb": {"objects": [5]}}, "input 'rgb' objects[0] is not a mapping"),
    ({"rgb": {"objects": [{"reliability": 1}]}}, "input 'rgb' objects[0] field 'name' is not a non-empty string"),
    (
        {"rgb": {"objects": [{"name": "a", "reliability": "high"}]}},
        "input 'rgb' objects[0] field 'reliability' is not a number: 'high'",
    ),
    (
        {"rgb": {"objects": [{"name": "a", "reliability": True}]}},
        "input 'rgb' objects[0] field 'reliability' is not a number: True",
    ),
    (
        {"rgb": {"objects": [{"name": "a", "reliability": float("nan")}]}},
        "input 'rgb' objects[0] field 'reliability' is not finite: nan",
    ),
    (
        {"rgb": {"objects": [{"name": "a", "reliability": 1.5}]}},
        "input 'rgb' objects[0] field 'reliability' = 1.5 is not in [0, 1]",
    ),
    (
        {"rgb": {"objects": [{"name": "a", "reliability": 1, "x": 2.0, "y": 0.5}]}},
        "input 'rgb' objects[0] fields 'x'/'y' = [2.0, 0.5] are not normalized image coordinates",
    ),
    (
        {"rgb": {"objects": [], "width": 0, "height": 480}},
        "input 'rgb' fields 'width'/'height' are not a whole image size: (0.0, 480.0)",
    ),
    ({"rgb": {"objects": [], "width": "640", "height": 480}}, "input 'rgb' field 'width' is not a number: '640'"),
    (
        {"depth": {"objects": [{"name": "box", "reliability": 1, "x": 0, "y": 0}]}},
        "input 'depth' objects[0] field 'z' is not a number: None",
    ),
    (
        {"depth": {"objects": [{"name": "box", "reliability": 1, "x": math.inf, "y": 0, "z": 1}]}},
        "input 'depth' objects[0] field 'x' is not finite: inf",
    ),
]


def test_data_must_be_a_mapping_of_inputs() -> None:
    with pytest.raises(ValueError) as caught:
        fusion().process([1, 2], CTX)
    assert str(caught.value) == f"{OWNER} expects a mapping of input name to result, got list"


@pytest.mark.parametrize(("data", "message"), MALFORMED)
def test_malformed_inputs_name_the_input_and_field(data: Any, message: str) -> None:
    with pytest.raises(ValueError) as caught:
        fusion().process(data, CTX)
    assert str(caught.value) == f"{OWNER}: {message}"


# --------------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"dThreshold": 0}, "parameter 'dThreshold' = 0.0 must be greater than 0"),
        ({"lineSigma": -1}, "parameter 'lineSigma' = -1.0 must be greater than 0"),
        ({"minRange": 0}, "parameter 'minRange' = 0.0 must be greater than 0"),
        ({"minReliability": 2}, "parameter 'minReliability' = 2.0 is not in [0, 1]"),
        ({"cx": "nan"}, "parameter 'cx' = nan is not finite"),
        ({"minRange": "inf"}, "parameter 'minRange' = inf is not finite"),
        ({"inputs": "rgb line"}, "parameter 'inputs' entry 'rgb line' is not 'name: values' with a new name"),
        (
            {"inputs": "rgb: line; rgb: point"},
            "parameter 'inputs' entry 'rgb: point' is not 'name: values' with a new name",
        ),
        ({"inputs": "rgb: plane"}, "parameter 'inputs' for 'rgb' must be 'line' or 'point', got ['plane']"),
        ({"poses": "lidar: 0 0 0 0 0 0"}, "parameter 'poses' names 'lidar', not an input of 'inputs'"),
        ({"poses": "rgb: 0 0 0"}, "parameter 'poses' for 'rgb' needs 6 finite numbers, got ['0', '0', '0']"),
        (
            {"poses": "rgb: 0 0 0 0 0 nan"},
            "parameter 'poses' for 'rgb' needs 6 finite numbers, got ['0', '0', '0', '0', '0', 'nan']",
        ),
        (
            {"cameras": "depth: 525 525 319.5 239.5 640 480"},
            "parameter 'cameras' names 'depth', not a line input of 'inputs'",
        ),
        (
            {"cameras": "rgb: 525 525 319.5 239.5 640.5 480"},
            "parameter 'cameras' for 'rgb' needs fx, fy > 0 and a whole size",
        ),
        ({"sigmas": "rgb: 0"}, "parameter 'sigmas' for 'rgb' = 0.0 must be greater than 0"),
        ({"objects": "a: b c d"}, "parameter 'objects' for 'a' needs a shape and maybe a texture"),
        ({"maxSensors": 0}, "parameter 'maxSensors' = 0 must be at least 1"),
    ],
)
def test_bad_params_are_refused(params: Mapping[str, object], message: str) -> None:
    with pytest.raises(ParamError) as caught:
        fusion(params)
    assert str(caught.value) == f"{OWNER}: {message}"


def test_unknown_param_lists_the_accepted_ones() -> None:
    accepted = r"takes no parameter 'sigma' \(accepted: bases, calibrationHeight, calibrationWidth"
    with pytest.raises(ParamError, match=accepted):
        fusion({"sigma": 1})


def test_per_input_cameras_and_sigmas_are_used() -> None:
    plugin = fusion({"cameras": "pantilt: 300 300 160 120 320 240", "sigmas": "depth: 0.05"})
    assert plugin.cameras["pantilt"].fx == 300 and plugin.cameras["rgb"].fx == 525
    assert plugin.sigmas == {"rgb": 0.01, "depth": 0.05, "pantilt": 0.01}


# --------------------------------------------------------------------------- environment catalog


def test_the_environment_file_gives_shapes_and_textures() -> None:
    plugin = fusion({"objects": "box_orange: box orange_paint", "environment": "environment.xml"}, loc=LOC)
    with pytest.raises(RuntimeError, match="is not set up"):
        plugin.process({}, CTX)
    plugin.setup()
    assert plugin.catalog["cylinder_green_checker"] == ("cylinder", "green_checker")
    assert plugin.catalog["box_orange"] == ("box", "orange_paint")  # Params win
    (obj,) = plugin.process({"rgb": rgb(seen("box_cereal", RED, 0.7)), "depth": depth(("box", RED, 0.8))}, CTX)[
        "objects"
    ]
    assert (obj["name"], obj["shape"], obj["texture"]) == ("box_cereal", "box", "cereal_label")


def test_a_missing_environment_file_is_a_value_error(tmp_path: Path) -> None:
    plugin = fusion({"environment": "nowhere.xml"}, loc=Loc(str(tmp_path / "system.xml"), 1, 1, "/"))
    with pytest.raises(ValueError) as caught:
        plugin.setup()
    where = tmp_path / "nowhere.xml"
    assert str(caught.value) == f"{OWNER}: cannot use environment file: {where}:1:1: /: file not found"


def test_a_bad_environment_file_is_a_value_error(tmp_path: Path) -> None:
    (tmp_path / "empty.xml").write_text('<Part xmlns="urn:ckm:1" version="1.0"/>', encoding="utf-8")
    (tmp_path / "bad.xml").write_text('<Part xmlns="urn:ckm:1"><Bogus/></Part>', encoding="utf-8")
    loc = Loc(str(tmp_path / "system.xml"), 1, 1, "/")
    with pytest.raises(ValueError, match="has no Environment"):
        fusion({"environment": "empty.xml"}, loc=loc).setup()
    with pytest.raises(ValueError, match=r"plugin 'f' \(feature-fusion\): cannot use environment file: .*bad.xml:1"):
        fusion({"environment": "bad.xml"}, loc=loc).setup()


# --------------------------------------------------------------------------- the real depth pipeline


def test_real_depth_results_fuse_with_rgb_results_of_the_same_scene() -> None:
    """The depth service's output for the lab scene, with an RGB result shaped as keypoint-matching's.

    The RGB scene renderer pastes textures at random image places (not the depth scene's
    geometry), so the RGB detections are the projections of the depth scene's true centres.
    """
    scene = render_depth_scene(seed=3, resolution=(240, 320))
    metres = DepthAcquisition(Plugin(name="a", kind="depth-acquisition")).process(scene.depth, CTX)
    params = (Param(name="tolerance", value="0.03"), Param(name="minPoints", value="100"),
              *(Param(name=k, value=str(v)) for k, v in LAB_CAMERA.items()))
    clusters = EuclideanClustering(Plugin(name="c", kind="euclidean-clustering", params=params)).process(metres, CTX)
    model = (Param(name="model", value="models/lab_objects_shapes.pcd"),)
    shapes = KdTreeShapeClassifier(Plugin(name="s", kind="kdtree-shape-classifier", params=model, loc=LOC))
    shapes.setup()
    found = shapes.process(clusters, CTX)
    truth = {t.name: (t.x, t.y, t.z) for t in scene.truth}
    seen_rgb = rgb(seen("box_cereal", truth["box_cereal"], 0.62), seen("cylinder_red_stripes", truth["cylinder"], 0.58))
    plugin = fusion({"environment": "environment.xml", "objects": ""}, loc=LOC)
    plugin.setup()
    out = plugin.process({"rgb": seen_rgb, "depth": found, "pantilt": None}, CTX)
    assert msgpack.unpackb(msgpack.packb(out)) == out
    objects = {o["name"]: o for o in out["objects"]}
    assert set(objects) == {"box_cereal", "cylinder_red_stripes", "box", "sphere"}
    for name, true in (("box_cereal", "box_cereal"), ("cylinder_red_stripes", "cylinder")):
        obj = objects[name]
        given = next(
            o["reliability"] for o in found["objects"] if math.dist((o["x"], o["y"], o["z"]), truth[true]) < 0.1
        )
        assert obj["sources"] == ["depth", "rgb"] and obj["reliability"] > max(given, 0.62)
        assert math.dist(position(obj), truth[true]) < 0.05  # the visible surface's centroid, a few cm in front
    assert objects["box"]["sources"] == ["depth"] and objects["box"]["texture"] is None
    assert out["reliability"] > found["reliability"]


def test_the_fusion_names_its_inputs_itself() -> None:
    """D272: no lab default; a fusion without ``inputs`` is refused at its Plugin and says what it needs."""
    record = Plugin(name="f", kind="feature-fusion", params=(Param(name="objects", value=CATALOG),))
    with pytest.raises(ParamError, match="inputs"):
        FeatureFusion(record)
