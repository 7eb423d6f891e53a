"""Learn the RGB recognition's ORB keypoints from rendered views of the skinned objects (thesis §7.4.1, D175).

The flat texture images alone leave the simulated robots short of matches: at 0.6–0.7 m a VGA
camera of about 580 px focal length sees a 7 cm cylinder 40–90 pixels wide, its print curved,
shaded and resampled by TinyRenderer, and ORB describes most of its corners differently from the
sharp flat print. As a real system is trained on a turntable, this module renders each textured object
of the environment on its own (the others moved away; the workbench stays as background) from
all round it, at several distances and heights, runs ORB as the service does, keeps the keypoints
that fall on the object's side, places each in the print through the skin's texture mapping
(:func:`plugins.sim.skins.texture_point`) and writes them to the model file's ``views`` file
(:mod:`plugins.processing.views`). A keypoint already learnt (near the same print pixel with a
close descriptor) is not stored twice.

Reproducible: the views are a fixed grid (``DISTANCES`` × ``AZIMUTHS`` × ``HEIGHTS``), the
renderer deterministic. Run after changing the textures, the skins or the environment::

    nice -n 19 .venv/bin/python -m plugins.sim.orb_training --model M.yml --system S.xml --focal F

(the lab's own command, with its files and camera, is ``python -m ckm_lab.orb_views``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pybullet as p

import ckmconf
from ckmconf.model import Environment
from ckmconf.model.environment import Geometry25D
from plugins.processing.textures import TextureSpec, read_model
from plugins.processing.views import write_views

from .skins import texture_point
from .world import World

DISTANCES = (0.5, 0.8, 1.2)
"""Camera distances (m) to the object's axis: at the given focal, and halved (``SCALES``), they span
the sizes VGA and QVGA cameras see objects on a workbench at."""
AZIMUTHS = 12
"""Views round the object (every 30°, from 15°: none from exactly where a mission robot stands)."""
HEIGHTS = (0.05, 0.3)
"""Camera elevation above the object's centre, as a share of the distance (level to ~17° down)."""
WINDOW = 320
"""Side of the square render (pixels) around the object: the focal as at VGA, only the part that matters."""
FEATURES = 100
"""Strongest ORB keypoints per view (on the object)."""
SCALES = (1.0, 0.5)
"""Each view is also learnt halved (area average), as a QVGA profile's resize shows it."""
SAME_PIXEL = 0.02
"""A new keypoint this close to a learnt one of its object (share of the print's larger side)..."""
SAME_BITS = 64
"""... and within this many Hamming bits of its descriptor is the same keypoint seen again."""
STABLE = 2
"""Views a keypoint must be seen in to be kept: one seen once is mostly rendering noise."""
_BITS = np.array([bin(i).count("1") for i in range(256)], np.uint8)


def _hamming(one: npt.NDArray[np.uint8], many: npt.NDArray[np.uint8]) -> npt.NDArray[np.intp]:
    bits: npt.NDArray[np.intp] = _BITS[np.bitwise_xor(many, one)].sum(axis=1, dtype=np.intp)
    return bits


class Learner:
    """One object's learnt keypoints, without repeats."""

    def __init__(self, spec: TextureSpec) -> None:
        self.spec = spec
        self._points = np.empty((0, 2), np.float32)
        self._descriptors = np.empty((0, 32), np.uint8)
        self._seen = np.empty(0, np.intp)
        self._near = SAME_PIXEL * max(spec.width, spec.height)

    def __len__(self) -> int:
        return len(self._points)

    @property
    def points(self) -> npt.NDArray[np.float32]:
        """The learnt print pixels (N×2)."""
        return self._points

    @property
    def descriptors(self) -> npt.NDArray[np.uint8]:
        """The learnt descriptors (N×32)."""
        return self._descriptors

    def add(self, points: npt.NDArray[np.float32], descriptors: npt.NDArray[np.uint8]) -> int:
        """Count each descriptor at its print pixel: a close one known there is seen once more, else it
        is new; how many were new."""
        new = 0
        for point, descriptor in zip(points, descriptors, strict=True):
            at = self._points
            gap = np.abs(at[:, 0] - point[0])
            if self.spec.wrap:  # the print's left and right edges meet round the cylinder
                gap = np.minimum(gap, self.spec.width - gap)
            close = np.flatnonzero((gap < self._near) & (np.abs(at[:, 1] - point[1]) < self._near))
            if close.size:
                bits = _hamming(descriptor, self._descriptors[close])
                if bits.min() < SAME_BITS:
                    self._seen[close[int(np.argmin(bits))]] += 1
                    continue
            self._points = np.vstack([self._points, point[None]])
            self._descriptors = np.vstack([self._descriptors, descriptor[None]])
            self._seen = np.append(self._seen, 1)
            new += 1
        return new

    def stable(self, views: int) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
        """The print pixels and descriptors of the keypoints seen in at least ``views`` views."""
        keep = self._seen >= views
        return self._points[keep], self._descriptors[keep]


def _render(world: World, eye: Sequence[float], target: Sequence[float], focal: float) -> tuple[Any, Any, Any, Any]:
    """Grey image, segmentation, and each pixel's map point (H×W×3) of one view from ``eye`` (``focal``: pixels)."""
    fov = math.degrees(2 * math.atan(WINDOW / 2 / focal))
    near, far = 0.05, 5.0
    view = p.computeViewMatrix(list(eye), list(target), [0, 0, 1])
    projection = p.computeProjectionMatrixFOV(fov, 1.0, near, far)
    _, _, rgb, zbuffer, mask = p.getCameraImage(WINDOW, WINDOW, view, projection, renderer=p.ER_TINY_RENDERER,
                                                physicsClientId=world.client)
    image = np.asarray(rgb, np.uint8).reshape(WINDOW, WINDOW, 4)[:, :, :3]
    depth = far * near / (far - (far - near) * np.asarray(zbuffer, float).reshape(WINDOW, WINDOW))
    forward = np.asarray(target, float) - np.asarray(eye, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    focal = WINDOW / 2 / math.tan(math.radians(fov) / 2)
    cols, rows = np.meshgrid(np.arange(WINDOW) + 0.5 - WINDOW / 2, np.arange(WINDOW) + 0.5 - WINDOW / 2)
    rays = forward + (cols[..., None] * right - rows[..., None] * up) / focal  # unit depth along forward
    points = np.asarray(eye, float) + depth[..., None] * rays
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    return grey, np.asarray(mask).reshape(WINDOW, WINDOW), points, image


def _placed(found: Sequence[Any], described: npt.NDArray[np.uint8], points: Any, inverse: Any, prism: Any,
            texture: TextureSpec, scale: float) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """The print pixels of a view's keypoints (found in the view resized by ``scale``) on the object's
    side, and their descriptors."""
    at, kept = [], []
    rotation = np.array(p.getMatrixFromQuaternion(inverse[1])).reshape(3, 3)
    for keypoint, descriptor in zip(found, described, strict=True):
        c, r = (min(int(v / scale), WINDOW - 1) for v in keypoint.pt)
        local = rotation @ points[r, c] + np.asarray(inverse[0])
        pixel = texture_point(prism, texture, (float(local[0]), float(local[1]), float(local[2])))
        if pixel is not None:
            at.append(pixel)
            kept.append(descriptor)
    return np.array(at, np.float32).reshape(-1, 2), np.array(kept, np.uint8).reshape(-1, 32)


def learn(environment: Environment, model: str | Path, focal: float, log: bool = False) -> dict[str, Learner]:
    """Each model object's keypoints learnt from the view grid (objects of ``environment`` only), seen
    by a camera of ``focal`` pixels at 640 columns (the recognising camera's)."""
    spec = read_model(model)
    orb = cv2.ORB.create(nfeatures=FEATURES)
    learners: dict[str, Learner] = {}
    with World(environment, catalog=spec, seed=0) as world:
        cid = world.client
        movable = {name: world.pose(body) for name, body in world.objects.items()
                   if p.getDynamicsInfo(body, -1, physicsClientId=cid)[0] > 0.0}
        for obj in environment.objects:
            texture = world.skins.get(obj.name)
            if texture is None or not isinstance(obj.geometry, Geometry25D):
                continue
            body = world.objects[obj.name]
            for other, (position, _) in movable.items():  # the others out of sight; this one in place
                far_away = [position[0], position[1], position[2] - (0 if other == obj.name else 50)]
                p.resetBasePositionAndOrientation(world.objects[other], far_away, movable[other][1],
                                                  physicsClientId=cid)
            centre, orientation = world.pose(body)
            inverse = p.invertTransform(centre, orientation)
            learner = learners[obj.name] = Learner(texture)
            for distance in DISTANCES:
                for k in range(AZIMUTHS):
                    for rise in HEIGHTS:
                        angle = 2 * math.pi * (k + 0.5) / AZIMUTHS
                        eye = (centre[0] + distance * math.cos(angle), centre[1] + distance * math.sin(angle),
                               centre[2] + rise * distance)
                        grey, mask, points, _ = _render(world, eye, centre, focal)
                        inside = cv2.erode((mask == body).astype(np.uint8), np.ones((5, 5), np.uint8))
                        for scale in SCALES:  # the render as is, and as a resized profile shows it
                            size = round(WINDOW * scale)
                            small = cv2.resize(grey, (size, size), interpolation=cv2.INTER_AREA)
                            where = cv2.resize(inside, (size, size), interpolation=cv2.INTER_NEAREST)
                            found, described = orb.detectAndCompute(small, where)
                            if described is not None:
                                learner.add(*_placed(found, np.asarray(described, np.uint8), points, inverse,
                                                     obj.geometry.prism, texture, scale))
            if log:
                print(f"{obj.name}: {len(learner)} keypoints, {len(learner.stable(STABLE)[0])} in {STABLE}+ views",
                      flush=True)
        for name, (position, orientation) in movable.items():
            p.resetBasePositionAndOrientation(world.objects[name], position, orientation, physicsClientId=cid)
    return learners


WRITTEN_BY = "nice -n 19 .venv/bin/python -m plugins.sim.orb_training"


def main(argv: Sequence[str] | None = None, written_by: str = WRITTEN_BY) -> int:
    """Learn the views of the model file's objects and write its ``views`` file (``written_by``: the
    command its header names)."""
    parser = argparse.ArgumentParser(prog="python -m plugins.sim.orb_training", description=__doc__.split("\n")[0])
    parser.add_argument("--model", required=True, help="the model file")
    parser.add_argument("--system", required=True, help="the system whose environment to render")
    parser.add_argument("--focal", type=float, required=True,
                        help="focal length (pixels at 640 columns) of the camera that recognises the objects")
    args = parser.parse_args(argv)
    spec = read_model(args.model)
    if not spec.views:
        parser.error(f"{args.model} names no 'views' file")
    system = ckmconf.load(args.system, strict=False).system
    if system is None or system.environment is None:
        parser.error(f"{args.system} has no environment")
    learners = learn(system.environment, args.model, args.focal, log=True)
    header = [
        f"ORB keypoints learnt from rendered views of {Path(args.model).name}'s objects (D175).",
        f"Written by: {written_by} (do not edit by hand).",
        f"Views: distances {' '.join(map(str, DISTANCES))} m x {AZIMUTHS} azimuths x heights "
        f"{' '.join(map(str, HEIGHTS))} (share of the distance); {WINDOW} px square at focal {args.focal} px.",
        "Format: object x y descriptor (texture pixels; 32 bytes in hex).",
    ]
    rows = [(name, float(x), float(y), bytes(d)) for name, learner in learners.items()
            for (x, y), d in zip(*learner.stable(STABLE), strict=True)]
    count = write_views(Path(args.model).parent / spec.views, rows, header)
    print(f"wrote {count} keypoints to {Path(args.model).parent / spec.views}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
