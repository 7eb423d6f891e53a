"""Keypoints learnt from rendered views (plugins/processing/views.py, D175) and prints wrapped round a
cylinder (``wrap``): the views file's format and errors, its place in the model, and the matcher
unwrapping a print seen across its seam."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
from ckm_lab.scenes import USECASE_MODEL

from plugins.processing import textures
from plugins.processing.recognition import OrbKeypoints
from plugins.processing.textures import read_model
from plugins.processing.views import read_views, write_views
from tests.plugins.processing.test_recognition import CTX, matcher, plugin

DESCRIPTOR = "ab" * 32


@pytest.mark.parametrize(
    ("lines", "message"),
    [
        ("a 1 2\n", "v.txt:2: expected 'object x y descriptor', got 3 fields"),
        (f"b 1 2 {DESCRIPTOR}\n", "v.txt:2: object 'b' is not in the model (known: a)"),
        ("a 1 2 abcd\n", "v.txt:2: a descriptor has 32 bytes, this one 2"),
        (f"a one 2 {DESCRIPTOR}\n", "v.txt:2: could not convert string to float: 'one'"),
        ("a 1 2 zz\n", "v.txt:2: non-hexadecimal number found in fromhex() arg at position 0"),
        ("", "v.txt: no keypoints"),
    ],
)
def test_views_file_errors_name_the_file_and_line(tmp_path: Path, lines: str, message: str) -> None:
    """The keypoints learnt from rendered views (D175): a bad line is named, as in the model file."""
    path = tmp_path / "v.txt"
    path.write_text("# learnt views\n" + lines, encoding="utf-8")
    with pytest.raises(ValueError) as error:
        read_views(path, ["a"])
    assert str(error.value) == f"{path}{message[5:]}"


def test_views_are_written_and_read_back_into_the_model(tmp_path: Path) -> None:
    """A views file round-trips, and build_model stacks its keypoints after the flat texture's."""
    rows = [("a", 10.0, 20.5, bytes(range(32))), ("a", 3.0, 4.0, bytes(32))]
    assert write_views(tmp_path / "v.txt", rows, ["header", ""]) == 2
    descriptors, points, labels = read_views(tmp_path / "v.txt", ["a"])
    assert labels.tolist() == [0, 0]
    assert descriptors.tolist() == [list(range(32)), [0] * 32] and points.tolist() == [[10.0, 20.5], [3.0, 4.0]]
    (tmp_path / "m.yml").write_text("views: v.txt\nobjects:\n  - name: a\n    seed: 3\n", encoding="utf-8")
    model = textures.build_model(tmp_path / "m.yml")
    assert model.descriptors[-2:].tolist() == descriptors.tolist() and model.labels[-2:].tolist() == [0, 0]
    (tmp_path / "m.yml").write_text("views: none.txt\nobjects:\n  - name: a\n", encoding="utf-8")
    with pytest.raises(ValueError) as error:
        textures.build_model(tmp_path / "m.yml")
    assert str(error.value) == (f"{tmp_path / 'm.yml'}: cannot read its views file {tmp_path / 'none.txt'}: "
                                "No such file or directory")


def test_a_print_wrapped_round_a_cylinder_is_found_across_its_seam() -> None:
    """The red print's right half then its left half (as round a can): with ``wrap`` the matcher unwraps
    the copies, explains more matches and puts the centre in the middle of what is seen (D175)."""
    spec = next(o for o in read_model(USECASE_MODEL).objects if o.name == "cylinder_red_stripes")
    assert spec.wrap
    texture = textures.render_texture(spec)
    seam = cv2.resize(np.roll(texture, texture.shape[1] // 2, axis=1), None, fx=0.8, fy=0.8,
                      interpolation=cv2.INTER_AREA)
    canvas = np.full((480, 640, 3), 128, np.uint8)
    h, w = seam.shape[:2]
    canvas[100 : 100 + h, 250 : 250 + w] = seam
    orb = OrbKeypoints(plugin("orb-keypoints", {"features": 500}))
    orb.setup()
    keypoints = orb.process(canvas, CTX)
    match = matcher()
    (unwrapped,) = match.process(keypoints, CTX)["objects"]
    assert match.model is not None
    match.model = dataclasses.replace(match.model, wraps=(False,) * len(match.model.names))
    (flat,) = match.process(keypoints, CTX)["objects"]
    assert unwrapped["name"] == flat["name"] == "cylinder_red_stripes"
    assert unwrapped["inliers"] > 1.2 * flat["inliers"]
    middle = (250 + w / 2) / 640
    assert abs(unwrapped["x"] - middle) < 0.02 < abs(flat["x"] - middle)
