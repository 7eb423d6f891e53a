"""ckm-bench fusion: Fig. 7.18 and 7.19 from the simulated Xtion (issue J point 7, thesis §7.4.1, eq. 6.41).

Every observation is one render of the use case's lab (``fusion_scene.Lab``: the workbench's
objects wearing their learnt prints, the Turtlebot at a sampled pose), run through the REAL RGB
pipeline (ORB keypoints matched to the texture model) and the REAL depth pipeline (clusters
classified in the KD-tree of shapes), then fused by ``feature-fusion`` in the map frame. The
ground truth only scores the three results:

- depth: the recognised cluster within ``NEAR`` of the object's centre (map frame) names its shape;
- RGB: the detection whose projection ray passes within ``NEAR`` of the centre names the object;
- fused: the fused object there (its point, or its ray for an RGB-only one) names the object
  (an untextured object: its shape).

Fig. 7.18 (``--observations`` per object, default 1,000): per object and method the detection
rate, classification accuracy, reliability mean and standard deviation over the results that are
not wrong (right, or a fused object named by its shape only), the
cylinders' same-shape discrimination (fused objects named by a texture: the right one?), the
fused values at the bound 1.0 and their position error. Views are sampled around the workbench
(camera 0.5–1.0 m from the aimed object, ±40° around its front, the object anywhere in the
field of view); each render is scored for every workbench object in view. Fig. 7.19: the robot
approaches one cylinder from 1.8 m and 0.5 rad off its axis to 0.6 m in front of it, aligned.
Plots (matplotlib), ``results.json``, ``results.txt`` and ``views.json`` (every scored observation) go
to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from ckm_lab.shapes import XTION

from benchmarks.fusion_report import describe, plot_approach, plot_reliability, summarise
from benchmarks.fusion_scene import LINK, Lab, Target, View
from plugins.processing.mounts import model_path, read_mount

__all__ = ["describe", "run"]

NEAR = 0.08
"""How far (m) from an object's centre a result may lie to be about it: its radius and the visible
surface's offset, well below the 0.35 m between the workbench's objects."""
MIN_PIXELS = 400
"""Pixels of an object (at the render's resolution, VGA equivalent) for it to count as in view."""
TABLE = (7.28, 8.92, 5.83, 6.57)
"""The workbench's footprint (x0, x1, y0, y1) grown by 2 cm: the camera and mast stay out of it."""
METHODS = ("depth", "rgb", "fused")
DISTANCES = (0.5, 1.0)
"""Camera-to-object distances sampled (m): the range before a grasp where the RGB pipeline still finds
the prints at VGA (beyond ~0.8 m it rarely does); the workbench keeps the camera ≥ 0.46 m away."""


def _camera_offset() -> tuple[float, float]:
    """The optical frame's (x, y) in the Turtlebot's base frame (URDF mount)."""
    mount = read_mount(model_path("turtlebot", Path()), LINK).pose()
    return float(mount.translation[0]), float(mount.translation[1])


def base_for(camera: tuple[float, float], yaw: float, offset: tuple[float, float]) -> tuple[float, float, float]:
    """The base pose that puts the camera at ``camera`` (map x, y) with heading ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    return camera[0] - (c * offset[0] - s * offset[1]), camera[1] - (s * offset[0] + c * offset[1]), yaw


def _outside_table(x: float, y: float) -> bool:
    x0, x1, y0, y1 = TABLE
    return not (x0 < x < x1 and y0 < y < y1)


def _ray_gap(centre: np.ndarray[Any, Any], origin: np.ndarray[Any, Any], direction: np.ndarray[Any, Any]) -> float:
    t = max(float((centre - origin) @ direction), 0.0)
    return float(np.linalg.norm(centre - origin - t * direction))


def score(lab: Lab, view: View, target: Target) -> dict[str, Any]:
    """Each method's result about ``target`` in ``view``: reliability, name, correct (None: missed)."""
    rotation, position = view.camera
    centre = np.asarray(target.centre)
    offset = centre - position
    turn = math.atan2(offset[1], offset[0]) - view.pose[2]
    out: dict[str, Any] = {
        "distance": float(np.hypot(offset[0], offset[1])),
        "bearing": math.atan2(math.sin(turn), math.cos(turn)),
        "pixels": view.pixels[target.name],
    }
    best: dict[str, Any] | None = None
    for obj in view.depth["objects"]:
        if obj["name"] == "unknown":
            continue
        at = rotation @ np.array([obj["x"], obj["y"], obj["z"]]) + position
        if math.hypot(*(at[:2] - centre[:2])) < NEAR and abs(at[2] - centre[2]) < 2 * NEAR:
            best = obj if best is None or obj["reliability"] > best["reliability"] else best
    out["depth"] = None if best is None else (best["reliability"], best["name"], best["name"] == target.shape)
    focal, cx, cy = lab.fusion.cameras["rgb"].fx, lab.fusion.cameras["rgb"].cx, lab.fusion.cameras["rgb"].cy
    width, height = lab.size
    local = rotation.T @ (centre - position)
    best = None
    for obj in view.rgb["objects"]:
        ray = np.array([(obj["x"] * width - cx) / focal, (obj["y"] * height - cy) / focal, 1.0])
        if _ray_gap(local, np.zeros(3), ray / np.linalg.norm(ray)) < NEAR:
            best = obj if best is None or obj["reliability"] > best["reliability"] else best
    out["rgb"] = None if best is None else (best["reliability"], best["name"], best["name"] == target.name)
    best, gap = None, math.inf
    for obj in view.fused["objects"]:
        if obj["x"] is not None:
            at = np.array([obj["x"], obj["y"], obj["z"]])
            near = math.hypot(*(at[:2] - centre[:2])) < NEAR and abs(at[2] - centre[2]) < 2 * NEAR
            miss = float(np.linalg.norm(at - centre))
        else:
            miss = _ray_gap(centre, np.asarray(obj["origin"]), np.asarray(obj["direction"]))
            near = miss < NEAR
        if near and (best is None or obj["reliability"] > best["reliability"]):
            best, gap = obj, miss
    if best is None:
        out["fused"] = None
    else:
        right = best["name"] == target.name or (not target.textured and best["shape"] == target.shape)
        out["fused"] = (best["reliability"], best["name"], right)
        out["fused_sources"] = sorted(best["sources"])
        out["fused_error"] = gap if best["x"] is not None else None
    return out


def sample_views(lab: Lab, per_object: int, seed: int) -> tuple[dict[str, list[dict[str, Any]]], int]:
    """Render until every workbench object has ``per_object`` scored observations; also the renders."""
    rng = np.random.default_rng(seed)
    offset = _camera_offset()
    scored: dict[str, list[dict[str, Any]]] = {name: [] for name in lab.targets}
    renders = 0
    while min(len(v) for v in scored.values()) < per_object:
        aim = lab.targets[min(scored, key=lambda n: (len(scored[n]), n))]
        distance = float(rng.uniform(*DISTANCES))
        around = -math.pi / 2 + float(rng.uniform(-0.7, 0.7))
        camera = (aim.centre[0] + distance * math.cos(around), aim.centre[1] + distance * math.sin(around))
        yaw = around + math.pi + float(rng.uniform(-0.3, 0.3))
        pose = base_for(camera, yaw, offset)
        mast = (pose[0] - 0.06 * math.cos(yaw), pose[1] - 0.06 * math.sin(yaw))
        if not (_outside_table(*camera) and _outside_table(*mast)):
            continue
        view = lab.observe(pose)
        renders += 1
        scale = (XTION.width * XTION.height) / (lab.size[0] * lab.size[1])
        for target in lab.targets.values():
            if len(scored[target.name]) < per_object and view.pixels[target.name] * scale >= MIN_PIXELS:
                scored[target.name].append(score(lab, view, target))
    return scored, renders


def approach(lab: Lab, name: str, steps: int) -> list[dict[str, Any]]:
    """Fig. 7.19: from 1.8 m and 0.5 rad off the object's axis (heading 0.3 rad off) to 0.6 m, aligned."""
    target, offset = lab.targets[name], _camera_offset()
    track = []
    for k in range(steps):
        progress = 1.0 - math.exp(-4.0 * k / max(steps - 1, 1))
        progress /= 1.0 - math.exp(-4.0)
        distance = 1.8 + (0.6 - 1.8) * progress
        around = -math.pi / 2 + 0.5 * (1.0 - progress)
        camera = (target.centre[0] + distance * math.cos(around), target.centre[1] + distance * math.sin(around))
        yaw = around + math.pi + 0.3 * (1.0 - progress)
        view = lab.observe(base_for(camera, yaw, offset))
        row = score(lab, view, target)
        # a result counts when it is about the object and not wrong (a fused object named by its shape only)
        track.append(
            {"step": k, "distance": row["distance"], "angle": row["bearing"]}
            | {
                m: (row[m][0] if row[m] is not None and (row[m][2] or row[m][1] == target.shape) else 0.0)
                for m in METHODS
            }
        )
    return track


def run(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Run the benchmark; the result dict (also ``results.json`` and ``results.txt`` in ``--out``)."""
    parser = argparse.ArgumentParser(prog="ckm-bench fusion", description=__doc__.splitlines()[0])
    parser.add_argument("--observations", type=int, default=1000, help="scored observations per object")
    parser.add_argument("--approach-steps", type=int, default=60, help="renders along the Fig. 7.19 approach")
    parser.add_argument("--approach-object", default="cylinder_green_checker", help="the object approached")
    parser.add_argument("--rgb-profile", default="VGA", choices=("VGA", "QVGA", "QQVGA"), help="RGBRecog profile")
    parser.add_argument("--depth-profile", default="QVGA", choices=("VGA", "QVGA", "QQVGA"), help="DepthRecog profile")
    parser.add_argument("--seed", type=int, default=1, help="seeds the views and the depth noise")
    parser.add_argument("--out", type=Path, default=Path("runs/bench-fusion"), help="where plots and results go")
    args = parser.parse_args(list(argv or []))
    if args.observations < 1 or args.approach_steps < 2:
        parser.error("--observations must be at least 1 and --approach-steps at least 2")
    start = time.perf_counter()
    lab = Lab(args.rgb_profile, args.depth_profile, seed=args.seed)
    try:
        if args.approach_object not in lab.targets:
            parser.error(f"--approach-object {args.approach_object!r} is not one of {', '.join(lab.targets)}")
        scored, renders = sample_views(lab, args.observations, args.seed)
        track = approach(lab, args.approach_object, args.approach_steps)
    finally:
        lab.close()
    elapsed = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {
        "observations_per_object": args.observations,
        "renders": renders + args.approach_steps,
        "seconds": round(elapsed, 1),
        "ms_per_render": round(1000 * elapsed / (renders + args.approach_steps), 1),
        "profiles": {"rgb": args.rgb_profile, "depth": args.depth_profile},
        **summarise(scored),
        "approach": {"object": args.approach_object, "track": track},
        "plots": [str(args.out / "fig7_18_reliability.png"), str(args.out / "fig7_19_approach.png")],
    }
    plot_reliability(scored, args.out / "fig7_18_reliability.png")
    plot_approach(track, args.approach_object, args.out / "fig7_19_approach.png")
    (args.out / "results.json").write_text(json.dumps(result, indent=2))
    (args.out / "views.json").write_text(json.dumps(scored))  # every scored observation, for re-analysis
    (args.out / "results.txt").write_text("\n".join(f"{k}: {v}" for k, v in describe(result)) + "\n")
    return result
