"""The pictures of the HTML run report (:mod:`.html_report`) as PNG bytes, drawn with matplotlib.

- :func:`map_png`: Fig. 7.16 — the ``<Environment>`` of the configuration (schemas/environment.xsd,
  §6.1: map bounds as walls, areas, avoided areas, object footprints, a flat marking (D294) as a pale
  dashed outline) drawn from the ``ckmconf`` records, with the trajectories, the zoom-map areas and
  where the target was recognised.
- :func:`reliability_png`: Fig. 7.19 — the target's recognition reliability against time (every
  recognition topic) and against its distance to the robot (the fused result).
- :func:`image_png`: a camera frame (Fig. 7.22, 7.24).

No pyplot: figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas, so nothing
global is touched and no display is needed.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon
from matplotlib.patches import Rectangle as Box

from ckmconf.model.environment import Circle as CircleRecord
from ckmconf.model.environment import Environment, EnvObject, Geometry2D, Geometry3D, Geometry25D
from ckmconf.model.environment import Polygon as PolygonRecord
from ckmconf.model.environment import Rectangle as RectangleRecord

SNAPSHOT_WIDTH = 480
"""Camera frames wider than this (px) are subsampled by a whole step before encoding."""
Approach = tuple[float, float, float | None, float]  # run time, distance (m), bearing (°), reliability
Track = tuple[str, str, Sequence[tuple[float, float, float]]]  # label, colour, (t, x, y)


def figure_png(fig: Figure, dpi: int = 100) -> bytes:
    """The figure as PNG bytes (Agg canvas)."""
    FigureCanvasAgg(fig)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def _placed(obj: EnvObject, x: float, y: float) -> tuple[float, float]:
    """A point of the object's own frame in the map frame (its ``<Pose>``)."""
    c, s = math.cos(obj.pose.yaw), math.sin(obj.pose.yaw)
    return obj.pose.x + c * x - s * y, obj.pose.y + s * x + c * y


def _atoms(obj: EnvObject) -> list[CircleRecord | RectangleRecord | PolygonRecord]:
    geometry = obj.geometry
    if isinstance(geometry, Geometry2D):
        return list(geometry.atoms)
    if isinstance(geometry, Geometry25D):
        return [geometry.prism.base]
    if isinstance(geometry, Geometry3D):
        return [p.base for p in geometry.prisms]
    return []


def is_marking(obj: EnvObject) -> bool:
    """Whether the object is a flat marking (``<Geometry2D height="0">``, D294): drawn, but nobody's obstacle."""
    return isinstance(obj.geometry, Geometry2D) and obj.geometry.marking


def _footprint(obj: EnvObject, atom: CircleRecord | RectangleRecord | PolygonRecord, color: str) -> Circle | Polygon:
    # a marking: a pale fill in a dashed outline, under the obstacles (a robot's track crosses it)
    style = {"facecolor": color, "edgecolor": "black", "lw": 0.5, "zorder": 1.5}
    if is_marking(obj):
        style = {"facecolor": color, "edgecolor": "#555555", "lw": 0.8, "ls": "--", "alpha": 0.45, "zorder": 1.2}
    if isinstance(atom, CircleRecord):
        return Circle(_placed(obj, atom.x, atom.y), atom.radius, **style)
    if isinstance(atom, RectangleRecord):
        c, s = math.cos(atom.yaw), math.sin(atom.yaw)
        corners = [(sx * atom.width / 2, sy * atom.depth / 2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        points = [_placed(obj, atom.x + c * u - s * v, atom.y + s * u + c * v) for u, v in corners]
    else:
        points = [_placed(obj, v.x, v.y) for v in atom.vertices]
    return Polygon(points, closed=True, **style)


def draw_environment(ax: Axes, env: Environment, base: Path | None = None) -> None:
    """The ``<Environment>`` on ``ax``: map image (when given), bounds, areas, avoided areas, objects."""
    bounds = env.map
    if bounds.image and bounds.resolution and base is not None and (base / bounds.image).is_file():
        from matplotlib.image import imread

        picture = imread(base / bounds.image)
        height, width = picture.shape[:2]
        extent = (
            bounds.xmin,
            bounds.xmin + width * bounds.resolution,
            bounds.ymin,
            bounds.ymin + height * bounds.resolution,
        )
        ax.imshow(picture, extent=extent, cmap="gray", alpha=0.5, zorder=0)
    ax.add_patch(
        Box(
            (bounds.xmin, bounds.ymin), bounds.xmax - bounds.xmin, bounds.ymax - bounds.ymin, fill=False, lw=3, zorder=1
        )
    )
    for area in env.areas:
        ax.add_patch(Polygon(area.points(), closed=True, facecolor="#d6eaf8", edgecolor="#2e86c1", lw=0.8, zorder=1))
        xs, ys = zip(*area.points(), strict=True) if area.points() else ((0.0,), (0.0,))
        ax.text(min(xs) + 0.05, max(ys) - 0.05, area.name, fontsize=7, color="#1b4f72", va="top", zorder=2)
    for avoided in env.avoided:
        ax.add_patch(
            Polygon(avoided.points(), closed=True, facecolor="#7b7d7d", edgecolor="black", hatch="///", zorder=2)
        )
    colors = {t.name: t.color for t in env.textures}
    for obj in env.objects:
        color = colors.get(obj.texture or "", "#bbbbbb")
        for atom in _atoms(obj):
            ax.add_patch(_footprint(obj, atom, color))
    ax.set(xlim=(bounds.xmin - 0.2, bounds.xmax + 0.2), ylim=(bounds.ymin - 0.2, bounds.ymax + 0.2))
    ax.set_aspect("equal")


def map_png(
    env: Environment | None,
    tracks: Sequence[Track],
    zoom: Sequence[tuple[float, float, float, float, float]],
    target: Sequence[tuple[float, float]] = (),
    base: Path | None = None,
) -> bytes:
    """Fig. 7.16: the environment, trajectories (``(label, colour, [(t, x, y)])``), zoom-map areas
    (``(t, x, y, width, depth)``, numbered in order) and the target's recognised positions."""
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    ax = fig.subplots()
    if env is not None:
        draw_environment(ax, env, base)
    for i, (t, x, y, width, depth) in enumerate(zoom):
        ax.add_patch(Box((x - width / 2, y - depth / 2), width, depth, fill=False, ls="--", ec="tab:purple", lw=1))
        label = f"Z{i + 1} {t:.0f}s"
        ax.text(x - width / 2 + 0.05, y - depth / 2 + 0.05, label, fontsize=6, color="tab:purple", clip_on=True)
    for label, color, points in tracks:
        if not points:
            continue
        xs, ys = [p[1] for p in points], [p[2] for p in points]
        ax.plot(xs, ys, color=color, lw=1.5, label=label, zorder=4)
        ax.plot(xs[:1], ys[:1], marker="o", color=color, zorder=5)
        ax.plot(xs[-1:], ys[-1:], marker="s", color=color, zorder=5)
    if target:
        ax.scatter(
            [p[0] for p in target], [p[1] for p in target], s=6, color="tab:red", label="target recognised at", zorder=3
        )
    if zoom:
        ax.plot([], [], ls="--", color="tab:purple", label="zoom-map areas (Z1, Z2 …)")
    if tracks or target or zoom:
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.06), ncol=4)
    ax.set(xlabel="x (m)", ylabel="y (m)", title="Map, trajectories (○ start, □ end) and zoom-map areas")
    if env is None:
        ax.set_aspect("equal")
    return figure_png(fig)


def reliability_png(
    series: Sequence[tuple[str, Sequence[tuple[float, float]]]],
    approach: Sequence[Approach],
    spans: Sequence[tuple[str, float, float]] = (),
) -> bytes:
    """Fig. 7.19: reliability vs run time per topic (states shaded); with ``approach`` samples
    ``(t, distance, bearing° or None, reliability)`` also the distance and bearing to the target vs
    run time (the thesis' alignment in distance and angle) and the reliability vs distance."""
    fig = Figure(figsize=(10, 10 if approach else 4), layout="constrained")
    axes = fig.subplots(3 if approach else 1, 1, squeeze=False)[:, 0]
    top = axes[0]
    for i, (name, begin, end) in enumerate(spans):
        top.axvspan(begin, end, color=f"C{(i + 3) % 10}", alpha=0.12)
        top.text(begin, 1.02, name, fontsize=7, va="bottom", clip_on=False)
    for label, points in series:
        top.plot([p[0] for p in points], [p[1] for p in points], marker=".", markersize=3, lw=0.8, label=label)
    top.set(ylim=(-0.05, 1.08), xlabel="run time (s)", ylabel="reliability", title="Target recognition reliability")
    if series:
        top.legend(fontsize=8, loc="lower right")
    if approach:
        middle = axes[1]
        middle.sharex(top)
        middle.plot([a[0] for a in approach], [a[1] for a in approach], ".", markersize=3, color="C0")
        middle.set(ylabel="distance robot → target (m)", xlabel="run time (s)", title="Alignment with the target")
        bearings = [(a[0], a[2]) for a in approach if a[2] is not None]
        if bearings:
            twin = middle.twinx()
            twin.plot([b[0] for b in bearings], [b[1] for b in bearings], ".", markersize=3, color="C1")
            twin.set_ylabel("bearing of the target (°)", color="C1")
        bottom = axes[2]
        bottom.plot([a[1] for a in approach], [a[3] for a in approach], ".", markersize=3, color="C0")
        bottom.set(ylim=(-0.05, 1.05), xlabel="distance robot → target (m)", ylabel="fused reliability")
        bottom.invert_xaxis()  # the approach reads left to right
    return figure_png(fig)


def image_png(pixels: np.ndarray) -> bytes:
    """A camera frame as PNG: 8-bit grey or colour as it is, deeper or float images scaled to their range."""
    from matplotlib.image import imsave

    array = np.asarray(pixels)
    step = max(1, -(-array.shape[1] // SNAPSHOT_WIDTH))  # a frame is shown small: keep the page light
    array = array[::step, ::step]
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.dtype != np.uint8:
        finite = array[np.isfinite(array)] if array.dtype.kind == "f" else array
        low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
        scaled = (np.nan_to_num(array.astype(np.float64), nan=low) - low) / ((high - low) or 1.0)
        array = (np.clip(scaled, 0, 1) * 255).astype(np.uint8)
    buffer = io.BytesIO()
    if array.ndim == 2:
        imsave(buffer, array, cmap="gray", vmin=0, vmax=255, format="png")
    else:
        imsave(buffer, array[:, :, :4], format="png")
    return buffer.getvalue()
