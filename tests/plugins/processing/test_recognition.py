"""RGB recognition plugins (§7.2, §7.4.1): acquisition, ORB keypoints and texture matching, alone and
as the RGBDCamera's VGA / QVGA / QQVGA profiles run by the real Smart Plugin Topology."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import cv2
import msgpack
import numpy as np
import pytest
from ckm_lab.scenes import USECASE_MODEL, render_rgb_scene

from ckmconf.errors import ConfigError, Loc
from ckmconf.loader import load
from ckmconf.model import Param
from ckmconf.model.resources import Plugin, SmartResource
from plugins.processing import textures
from plugins.processing.recognition import CameraAcquisition, KeypointMatching, Keypoints, OrbKeypoints
from plugins.processing.textures import parse_model, read_model
from runtime.resources.spt import Context, ProcessingPlugin, Topology
from tests.conftest import CONFIGS
from tests.plugins.processing.camera_profiles import camera_with, every_profile

CTX = Context(frame=0, stamp=0.0, resource="RGBDCamera")
OBJECTS = [o.name for o in read_model(USECASE_MODEL).objects]
PROFILES = ("VGA", "QVGA", "QQVGA")


def plugin(kind: str, params: Mapping[str, object] | None = None, *, name: str = "p", loc: Loc | None = None) -> Plugin:
    given = tuple(Param(name=k, value=str(v)) for k, v in (params or {}).items())
    return Plugin(name=name, kind=kind, params=given, loc=loc)


def matcher(model: str = str(USECASE_MODEL)) -> KeypointMatching:
    match = KeypointMatching(plugin("keypoint-matching", {"model": model}, name="match"))
    match.setup()
    return match


@pytest.fixture(scope="module")
def rgb_camera() -> SmartResource:
    """The use case's RGBDCamera with only the RGB profiles (the depth plugins are tested elsewhere)."""
    return camera_with(CONFIGS / "usecase" / "resources.xml", PROFILES)


@pytest.fixture(scope="module")
def topology(rgb_camera: SmartResource) -> Iterator[Topology]:
    with every_profile(rgb_camera, PROFILES) as spt:
        yield spt


# ---------------------------------------------------------------------- parameters


@pytest.mark.parametrize(
    ("kind", "params", "message"),
    [
        ("camera-acquisition", {"encoding": "yuv422"}, "'encoding' = 'yuv422' is not one of rgb8, bgr8, mono8"),
        ("orb-keypoints", {"features": 0}, "parameter 'features' = 0 must be greater than 0"),
        ("orb-keypoints", {"scaleFactor": 1.0}, "parameter 'scaleFactor' = 1.0 must be greater than 1"),
        ("orb-keypoints", {"levels": 0}, "parameter 'levels' = 0 must be at least 1"),
        ("orb-keypoints", {"features": "many"}, "parameter 'features' = 'many' is not a int"),
        ("keypoint-matching", {}, "parameter 'model' = '' must be a file name"),
        ("keypoint-matching", {"model": "m.yml", "ratio": 1.5}, "parameter 'ratio' = 1.5 must be in (0, 1]"),
        ("keypoint-matching", {"model": "m.yml", "minMatches": 3}, "parameter 'minMatches' = 3 must be at least 4"),
        ("keypoint-matching", {"model": "m.yml", "support": 0}, "parameter 'support' = 0.0 must be greater than 0"),
        ("keypoint-matching", {"model": "m.yml", "nfeatures": 5}, "takes no parameter 'nfeatures'"),
    ],
)
def test_bad_params_are_refused_naming_the_plugin(kind: str, params: dict[str, object], message: str) -> None:
    classes: dict[str, type[ProcessingPlugin]] = {
        "camera-acquisition": CameraAcquisition,
        "orb-keypoints": OrbKeypoints,
        "keypoint-matching": KeypointMatching,
    }
    with pytest.raises(ValueError) as error:
        classes[kind](plugin(kind, params))
    assert f"plugin 'p' ({kind})" in str(error.value)
    assert message in str(error.value)


def test_a_bad_param_in_a_resource_is_a_config_error_at_its_plugin(rgb_camera: SmartResource) -> None:
    last = rgb_camera.plugins[-1]
    params = (*(p for p in last.params if p.name != "ratio"), Param(name="ratio", value="0"))
    bad = dataclasses.replace(last, params=params)
    with pytest.raises(ConfigError) as error:
        Topology(dataclasses.replace(rgb_camera, plugins=(*rgb_camera.plugins[:-1], bad)))
    assert bad.loc is not None
    assert str(error.value) == (
        f"{bad.loc.file}:{bad.loc.line}:{bad.loc.column}: {bad.loc.xpath}: "
        f"plugin '{bad.name}' (keypoint-matching): parameter 'ratio' = 0.0 must be in (0, 1]"
    )


# ---------------------------------------------------------------------- acquisition

RGB = np.random.default_rng(1).integers(0, 256, (6, 8, 3), dtype=np.uint8)


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        (RGB, RGB),
        ({"width": 8, "height": 6, "encoding": "rgb8", "data": RGB.tobytes()}, RGB),
        ({"width": 8, "height": 6, "encoding": "bgr8", "data": RGB[..., ::-1].tobytes()}, RGB),
        ({"width": 8, "height": 6, "data": RGB.tobytes()}, RGB),  # the Param's encoding
        ({"width": 8, "height": 6, "encoding": "mono8", "data": RGB[..., 0].tobytes()}, RGB[..., 0]),
    ],
)
def test_acquisition_decodes_each_encoding_to_rgb_or_mono(message: Any, expected: np.ndarray) -> None:
    image = CameraAcquisition(plugin("camera-acquisition")).process(message, CTX)
    assert image.dtype == np.uint8
    np.testing.assert_array_equal(image, expected)


def test_acquisition_reorders_bgr_arrays_when_the_param_says_so() -> None:
    acquire = CameraAcquisition(plugin("camera-acquisition", {"encoding": "bgr8"}))
    np.testing.assert_array_equal(acquire.process(RGB[..., ::-1].copy(), CTX), RGB)
    mono = CameraAcquisition(plugin("camera-acquisition", {"encoding": "mono8"}))
    np.testing.assert_array_equal(mono.process(RGB[..., 1].copy(), CTX), RGB[..., 1])


@pytest.mark.parametrize(
    ("message", "reason"),
    [
        ({"width": 8, "height": 6, "data": RGB.tobytes()[:-1]}, "rgb8 8x6 needs 144 bytes of data, got 143"),
        ({"width": 8, "height": 6, "encoding": "yuv422", "data": b""}, "unknown encoding 'yuv422'"),
        ({"width": 0, "height": 6, "data": b""}, "bad image size 0 x 6"),
        ({"width": 8, "data": b""}, "the message has no height"),
        ({"width": 8, "height": 6, "data": "text"}, "data is str, not bytes"),
        (RGB[..., 0], "rgb8 needs a uint8 (H, W, 3) array, got uint8 (6, 8)"),
        (RGB.astype(np.float32), "rgb8 needs a uint8 (H, W, 3) array, got float32 (6, 8, 3)"),
        ([1, 2, 3], "expects an image array or a width/height/data message"),
    ],
)
def test_acquisition_rejects_bad_messages_saying_what_is_wrong(message: Any, reason: str) -> None:
    with pytest.raises(ValueError) as error:
        CameraAcquisition(plugin("camera-acquisition", name="rgb_acquire")).process(message, CTX)
    assert "plugin 'rgb_acquire' (camera-acquisition)" in str(error.value)
    assert reason in str(error.value)


# ---------------------------------------------------------------------- ORB keypoints


def test_orb_keypoints_of_a_scene_without_touching_the_input() -> None:
    orb = OrbKeypoints(plugin("orb-keypoints", {"features": 200, "levels": 4}))
    image = render_rgb_scene(OBJECTS[:2], seed=3).image
    image.setflags(write=False)  # any write by the plugin would raise
    with pytest.raises(RuntimeError, match="is not set up"):
        orb.process(image, CTX)
    orb.setup()
    assert cv2.getNumThreads() == 1  # Param threads: one OpenCV thread, comparable CPU figures
    found = orb.process(image, CTX)
    assert isinstance(found, Keypoints)
    assert 150 <= len(found) <= 200
    assert found.points.shape == (len(found), 2) and found.shape == (480, 640)
    assert found.descriptors is not None and found.descriptors.shape == (len(found), 32)
    assert found.descriptors.dtype == np.uint8
    grey = np.rint(image @ np.array([0.299, 0.587, 0.114])).astype(np.uint8)
    assert abs(len(orb.process(grey, CTX)) - len(found)) <= 20  # grey input works the same
    with pytest.raises(ValueError, match="expects a uint8 RGB or grey image"):
        orb.process(image.astype(np.float32), CTX)
    orb.stop()


def test_a_flat_image_has_no_keypoints_and_no_detection() -> None:
    orb = OrbKeypoints(plugin("orb-keypoints"))
    orb.setup()
    found = orb.process(np.full((120, 160, 3), 90, np.uint8), CTX)
    assert len(found) == 0 and found.descriptors is None
    result = matcher().process(found, CTX)
    assert result == {"objects": [], "reliability": 0.0, "keypoints": 0, "width": 160, "height": 120}


# ---------------------------------------------------------------------- the model file


def test_the_model_file_is_relative_to_the_config_that_declares_the_plugin(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "two.yml").write_text(
        "objects:\n  - name: a\n    seed: 1\n  - name: b\n    pattern: checker\n    seed: 2\n", encoding="utf-8"
    )
    loc = Loc(str(tmp_path / "resources.xml"), 3, 5, "/Part/SmartResource/Plugin")
    match = KeypointMatching(plugin("keypoint-matching", {"model": "models/two.yml"}, loc=loc))
    match.setup()
    assert match.model is not None and match.model.names == ("a", "b")
    monkeypatch.chdir(tmp_path / "models")
    relative = KeypointMatching(plugin("keypoint-matching", {"model": "two.yml"}))  # no loc: the current directory
    relative.setup()
    assert relative.path == tmp_path / "models" / "two.yml"


def test_a_missing_model_file_names_the_path(tmp_path: Path) -> None:
    loc = Loc(str(tmp_path / "resources.xml"), 3, 5, "/Part/SmartResource/Plugin")
    match = KeypointMatching(plugin("keypoint-matching", {"model": "models/none.yml"}, name="match_vga", loc=loc))
    with pytest.raises(FileNotFoundError) as error:
        match.setup()
    assert str(error.value) == (
        f"[Errno 2] plugin 'match_vga' (keypoint-matching): cannot read model file "
        f"{tmp_path / 'models' / 'none.yml'}: No such file or directory"
    )


def test_a_malformed_model_file_names_the_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.yml"
    path.write_text("version: 1\nobjects:\n  - name: a\n    seed: seven\n", encoding="utf-8")
    with pytest.raises(ValueError) as error:
        matcher(str(path)).setup()
    assert str(error.value) == (
        f"plugin 'match' (keypoint-matching): bad model file: {path}:4: seed = 'seven' is not a int"
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("objects:\n  - name: a\n    colour: red\n", "m.yml:3: unknown key 'colour' (known: name, pattern,"),
        ("objects:\n  - name: a\n    seed: 1\n    seed: 2\n", "m.yml:4: 'seed' is given twice"),
        ("features: 10\n  levels: 2\n", "m.yml:2: indented line outside 'objects:'"),
        ("objects:\n    seed: 2\n", "m.yml:2: object fields must follow a '- name: ...' item"),
        ("objects:\n  - name: 'a\n", "m.yml:2: unterminated quote"),
        ("objects: a\n", "m.yml:1: 'objects:' takes an indented list, not a value"),
        ("just words\n", "m.yml:1: expected 'key: value', got 'just words'"),
        ("scales: 1 half\nobjects:\n  - name: a\n", "m.yml:1: scales = '1 half' is not a list of numbers"),
        ("version: 2\nobjects:\n  - name: a\n", "m.yml: unsupported model version (this release reads 1)"),
        ("features: 10\n", "m.yml: no objects"),
        ("objects:\n  - seed: 1\n", "m.yml: an object has no name"),
        ("objects:\n  - name: a\n  - name: a\n", "m.yml: object names repeat: a, a"),
        ("objects:\n  - name: a\n    pattern: marble\n", "m.yml: object 'a' has unknown pattern 'marble'"),
        ("objects:\n  - name: a\n    color: '#12'\n", "m.yml: object 'a': colour '#12' is not #RRGGBB"),
        ("objects:\n  - name: a\n    width: 8\n", "m.yml: object 'a' is smaller than 32 pixels"),
        ("scales: 0\nobjects:\n  - name: a\n", "m.yml: scales must be one or more numbers in (0, 4]"),
        ("objects:\n  - name: a\n    wrap: maybe\n", "m.yml:3: wrap = 'maybe' is not a boolean"),
    ],
)
def test_model_file_errors(text: str, message: str) -> None:
    with pytest.raises(ValueError) as error:
        parse_model(text, "m.yml")
    assert str(error.value).startswith(message)


def test_a_texture_without_keypoints_cannot_be_learnt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "grey.yml"
    path.write_text("objects:\n  - name: grey\n", encoding="utf-8")
    monkeypatch.setattr(textures, "render_texture", lambda spec: np.full((spec.height, spec.width, 3), 128, np.uint8))
    with pytest.raises(ValueError) as error:
        textures.build_model(path)
    assert str(error.value) == f"{path}: object 'grey' has 0 keypoints; its texture is too plain"


def test_the_use_case_model_describes_the_textured_objects_of_the_environment() -> None:
    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    assert environment is not None
    textures = {t.name: t for t in environment.textures}
    patterned = {o.name: textures[o.texture] for o in environment.objects if o.texture and o.tag in ("box", "cylinder")}
    model = read_model(USECASE_MODEL)
    for spec in model.objects:
        texture = patterned.pop(spec.name)
        assert (spec.pattern, spec.color.upper(), spec.secondary.upper()) == (
            texture.pattern,
            texture.color.upper(),
            (texture.secondary or "").upper(),
        )
    assert [t.pattern for t in patterned.values()] == ["plain"]  # only the plain box is left to the depth service


# ---------------------------------------------------------------------- recognition


def _run(topology: Topology, scene: Any) -> Mapping[str, dict[str, Any]]:
    return topology.run(scene).outputs


def test_the_three_profiles_find_the_objects_and_only_them(topology: Topology) -> None:
    reliability: dict[str, list[float]] = {name: [] for name in PROFILES}
    found: dict[str, int] = dict.fromkeys(PROFILES, 0)
    shown = 0
    for seed in range(12):
        present = OBJECTS[seed % 4 :][:2] + OBJECTS[: max(0, seed % 4 - 2)]
        scene = render_rgb_scene(present, seed=seed)
        shown += len(present)
        for profile, output in _run(topology, scene.image).items():
            names = [o["name"] for o in output["objects"]]
            assert set(names) <= set(present), f"{profile} seed {seed} reports absent objects {names}"
            found[profile] += len(names)
            reliability[profile].append(output["reliability"])
            for obj in output["objects"]:
                x, y = scene.objects[obj["name"]].centre
                assert abs(obj["x"] - x) < 0.03 and abs(obj["y"] - y) < 0.03
                assert 0.0 < obj["reliability"] < 1.0 and obj["inliers"] <= obj["matches"]
    assert found["VGA"] == shown  # every object at VGA
    assert found["QVGA"] >= 0.75 * shown
    means = [float(np.mean(reliability[name])) for name in PROFILES]
    assert means[0] > means[1] > means[2], means  # reliability falls with resolution


def test_a_close_object_is_found_even_at_qqvga(topology: Topology) -> None:
    for seed, name in enumerate(OBJECTS):
        scene = render_rgb_scene([name], seed=seed, scale=(0.55, 0.7))
        outputs = _run(topology, scene.image)
        assert [o["name"] for o in outputs["QQVGA"]["objects"]] == [name]


def test_a_scene_without_objects_reports_none(topology: Topology) -> None:
    for seed in range(4):
        outputs = _run(topology, render_rgb_scene([], seed=seed).image)
        assert all(out["objects"] == [] and out["reliability"] == 0.0 for out in outputs.values())


def test_a_raw_message_gives_the_same_result_as_the_array(topology: Topology) -> None:
    image = render_rgb_scene(OBJECTS[1:3], seed=5).image
    message = {"width": 640, "height": 480, "encoding": "bgr8", "data": image[..., ::-1].tobytes()}
    assert _run(topology, message) == _run(topology, image)


def test_outputs_are_msgpack_able_and_the_plugins_have_no_state(topology: Topology) -> None:
    output = _run(topology, render_rgb_scene(OBJECTS, seed=7).image)["VGA"]
    assert msgpack.unpackb(msgpack.packb(output)) == output
    assert output["keypoints"] == 500 and (output["width"], output["height"]) == (640, 480)
    assert topology.state() == {}


def test_the_shared_acquisition_runs_once_per_frame(topology: Topology) -> None:
    topology.reset_stats()
    for seed in range(3):
        topology.run(render_rgb_scene(OBJECTS[:1], seed=seed).image)
    stats = topology.stats()
    assert stats["rgb_acquire"].calls == 3
    assert all(stats[f"match_{name.lower()}"].calls == 3 for name in PROFILES)
