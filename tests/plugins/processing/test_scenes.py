"""Synthetic RGB scenes and object textures: deterministic, with ground truth that matches the pixels."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from ckm_lab.scenes import BACKGROUNDS, USECASE_MODEL, background, render_rgb_scene

from plugins.processing.textures import TextureSpec, read_model, render_texture

OBJECTS = [o.name for o in read_model(USECASE_MODEL).objects]


def test_the_same_seed_gives_the_same_frame() -> None:
    first = render_rgb_scene(OBJECTS, seed=11)
    again = render_rgb_scene(OBJECTS, seed=11)
    np.testing.assert_array_equal(first.image, again.image)
    assert {n: p.centre for n, p in first.objects.items()} == {n: p.centre for n, p in again.objects.items()}
    other = render_rgb_scene(OBJECTS, seed=12)
    assert not np.array_equal(first.image, other.image)


@pytest.mark.parametrize("resolution", [(480, 640), (240, 320), (120, 160)])
def test_frames_have_the_requested_resolution_and_every_object(resolution: tuple[int, int]) -> None:
    scene = render_rgb_scene(OBJECTS, resolution, seed=2)
    assert scene.image.shape == (*resolution, 3) and scene.image.dtype == np.uint8
    assert sorted(scene.objects) == sorted(OBJECTS)
    rows, cols = resolution
    for placement in scene.objects.values():
        assert 0.0 < placement.centre[0] < 1.0 and 0.0 < placement.centre[1] < 1.0
        assert placement.corners.shape == (4, 2)
        assert (placement.corners >= 0).all() and (placement.corners[:, 0] < cols).all()
        assert (placement.corners[:, 1] < rows).all()


def test_objects_do_not_overlap() -> None:
    for seed in range(10):
        scene = render_rgb_scene(OBJECTS, seed=seed)
        boxes = [cv2.boundingRect(p.corners) for p in scene.objects.values()]
        for i, (x, y, w, h) in enumerate(boxes):
            for u, v, s, t in boxes[i + 1 :]:
                assert x + w <= u + 1 or u + s <= x + 1 or y + h <= v + 1 or v + t <= y + 1


def test_the_ground_truth_points_at_the_pasted_texture() -> None:
    """Without noise, lighting or tilt, the pixels around a centre are the texture's centre pixels."""
    spec = read_model(USECASE_MODEL).objects[0]
    scene = render_rgb_scene([spec.name], seed=4, noise=0.0, lighting=0.0, rotation=0.0, perspective=0.0)
    placement = scene.objects[spec.name]
    x0, y0 = placement.corners.min(axis=0)
    x1, y1 = placement.corners.max(axis=0)
    assert abs((x0 + x1) / 2 / 640 - placement.centre[0]) < 1e-3
    assert abs((y0 + y1) / 2 / 480 - placement.centre[1]) < 1e-3
    inside = scene.image[int(y0) + 2 : int(y1) - 1, int(x0) + 2 : int(x1) - 1]
    size = (inside.shape[1], inside.shape[0])
    expected = cv2.resize(render_texture(spec), size, interpolation=cv2.INTER_AREA)
    assert np.abs(inside.astype(int) - expected.astype(int)).mean() < 25  # the same picture, resampled


def test_an_empty_noiseless_scene_is_the_background() -> None:
    scene = render_rgb_scene([], seed=3, noise=0.0, lighting=0.0)
    np.testing.assert_array_equal(scene.image, background(480, 640, 3 % BACKGROUNDS))
    assert scene.objects == {}


def test_noise_and_lighting_change_the_pixels_but_not_the_placements() -> None:
    clean = render_rgb_scene(OBJECTS[:2], seed=9, noise=0.0, lighting=0.0)
    noisy = render_rgb_scene(OBJECTS[:2], seed=9, noise=6.0, lighting=0.0)
    difference = noisy.image.astype(int) - clean.image.astype(int)
    assert 3.0 < difference.std() < 9.0
    assert {n: p.centre for n, p in clean.objects.items()} == {n: p.centre for n, p in noisy.objects.items()}


def test_unknown_repeated_or_too_many_objects_are_refused() -> None:
    with pytest.raises(ValueError, match=r"no object 'teapot' in .*lab_objects_orb.yml \(objects: cylinder_red"):
        render_rgb_scene(["teapot"])
    with pytest.raises(ValueError, match="objects repeat: box_cereal, box_cereal"):
        render_rgb_scene(["box_cereal", "box_cereal"])
    with pytest.raises(ValueError, match=r"cannot place .* without overlap: use fewer objects or a smaller scale"):
        render_rgb_scene(OBJECTS, scale=(0.8, 0.9))


def test_textures_are_deterministic_read_only_and_differ_by_seed() -> None:
    spec = TextureSpec("t", pattern="dots", color="#1F4E9A", secondary="#FFFFFF", seed=5, width=120, height=160)
    texture = render_texture(spec)
    assert texture.shape == (160, 120, 3) and not texture.flags.writeable
    render_texture.cache_clear()
    np.testing.assert_array_equal(render_texture(spec), texture)
    other = render_texture(TextureSpec("t", pattern="dots", color="#1F4E9A", secondary="#FFFFFF", seed=6))
    assert not np.array_equal(other[:160, :120], texture)
    with pytest.raises(ValueError, match="texture 'x': unknown pattern 'marble'"):
        render_texture(TextureSpec("x", pattern="marble"))
