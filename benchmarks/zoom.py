"""ckm-bench zoom: map-management time per perception update, whole map vs zoom map (thesis §6.1.3, §7.4.1).

Workload. A 60 m × 60 m floor holds N objects (100 → 100,000) scattered at random (5 % of them
mobile), so the density grows with N. A robot drives a fixed loop at 0.5 m/s; every 0.1 s it
perceives the (at most) ``PERCEPTIONS`` objects nearest to it within ``RANGE`` metres, with 3 cm
noise, and the map is updated (:func:`plugins.environment.perception.manage`). Two copies of
the same map and the same perceptions are managed two ways:

- **full** (eq. 6.1): every perception is compared with every map element, ``np × ne`` per update;
- **zoom** (eq. 6.2): the zoom map (8 m × 6 m, 2D, border 10 %, time-out 10 s, ``maxObjects``
  200) is moved when needed (``t_m'``, timed and included) and every perception is compared with
  the managed elements only, ``np × ne'``.

``full_ms`` / ``zoom_ms`` are the mean milliseconds per perception update. Eq. 6.1/6.2 are fitted
by least squares across sizes: ``t_i = a + b·np·ne`` and ``t'_i = a' + b'·np·ne'`` plus the
measured re-centring cost spread over the updates (``t_m'·moves/n``); both models sit next to the
measures in ``sizes``. The run also writes a Fig. 7.16-style picture (the use-case lab, a tour of
goal positions planned with :class:`~plugins.environment.planner.Planner`, the successive zoom
areas) and the time plot to ``--out``.
"""

from __future__ import annotations

import argparse
import gc
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.neighbors import KDTree

import ckmconf
from benchmarks.zoom_tour import LAB_GOALS, draw_tour, drive
from ckmconf.model.environment import Semantic
from plugins.environment.map_model import MapModel, small_object
from plugins.environment.perception import manage
from plugins.environment.semantics import SemanticDictionary
from plugins.environment.zoom import ZoomMap, ZoomSettings

SIDE = 60.0
PERCEPTIONS = 10
RANGE = 2.0
NOISE = 0.03
PERIOD = 0.1
SPEED = 0.5
ZOOM = ZoomSettings(mode="2D", width=8.0, depth=6.0, border=0.1, timeout=10.0, max_objects=200)
DEFAULT_SIZES = (100, 1000, 10_000, 100_000)
LAB = Path(__file__).resolve().parent.parent / "configs" / "usecase" / "environment.xml"
LOOP = [(10.0, 10.0), (50.0, 12.0), (48.0, 50.0), (12.0, 46.0), (10.0, 10.0)]


def scattered_map(objects: int, *, side: float = SIDE, seed: int = 1, mobile_share: float = 0.05) -> MapModel:
    """A ``side`` × ``side`` floor with ``objects`` small objects at random, some of them mobile."""
    rng = np.random.default_rng(seed)
    semantics = SemanticDictionary(
        [Semantic(tag="crate", dynamic="static"), Semantic(tag="cart", dynamic="mobile", max_speed=1.0)]
    )
    model = MapModel((0.0, 0.0, side, side), semantics=semantics, name=f"scattered-{objects}")
    xy = rng.uniform(0.3, side - 0.3, size=(objects, 2))
    mobile = rng.random(objects) < mobile_share
    model.add_many(
        [
            small_object(f"o{i}", "cart" if moving else "crate", x, y, radius=0.1)
            for i, ((x, y), moving) in enumerate(zip(xy.tolist(), mobile.tolist(), strict=True))
        ]
    )
    return model


def trajectory(updates: int, waypoints: Sequence[tuple[float, float]] = LOOP) -> np.ndarray:
    """``updates`` robot positions along the waypoints at :data:`SPEED`, one every :data:`PERIOD` s."""
    points = np.asarray(waypoints, dtype=float)
    legs = np.diff(points, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    along = (np.arange(updates) * SPEED * PERIOD) % lengths.sum()
    ends = np.cumsum(lengths)
    leg = np.searchsorted(ends, along, side="right").clip(max=len(legs) - 1)
    into = along - (ends[leg] - lengths[leg])
    positions: np.ndarray = points[leg] + legs[leg] * (into / lengths[leg])[:, None]
    return positions


def perceptions(model: MapModel, path: np.ndarray, seed: int) -> list[np.ndarray]:
    """What the robot perceives at each position: the nearest objects within :data:`RANGE`, with noise."""
    rng = np.random.default_rng(seed + 1)
    truth = model.xy.copy()
    tree = KDTree(truth)
    k = min(PERCEPTIONS, len(truth))
    distances, indices = tree.query(path, k=k)
    seen = []
    for near, rows in zip(distances, indices, strict=True):
        picked = truth[rows[near <= RANGE]]
        seen.append(picked + rng.normal(0.0, NOISE, size=picked.shape))
    return seen


def measure(objects: int, updates: int, seed: int = 1) -> dict[str, Any]:
    """Full vs zoom management of the same map and perceptions; times in ms per update."""
    path = trajectory(updates)
    full_map, zoom_map = scattered_map(objects, seed=seed), scattered_map(objects, seed=seed)
    seen = perceptions(full_map, path, seed)
    full_times, zoom_times, moves_s, managed = [], [], [], []
    full_counts: dict[str, int] = {}
    zoom_counts: dict[str, int] = {}
    # Two passes, not interleaved: the full map's 100,000-element scans would evict the zoom map's
    # data from the caches and charge it for the full map's garbage.
    gc.collect()
    for step, batch in enumerate(seen):
        started = time.perf_counter()
        counts = manage(full_map, batch, stamp=1000.0 + step * PERIOD)
        full_times.append(time.perf_counter() - started)
        for key, value in counts.items():
            full_counts[key] = full_counts.get(key, 0) + value
    zoom = ZoomMap(zoom_map, ZOOM)
    gc.collect()
    for step, ((x, y), batch) in enumerate(zip(path.tolist(), seen, strict=True)):
        stamp = 1000.0 + step * PERIOD
        started = time.perf_counter()
        moved = zoom.update(x, y, stamp)
        between = time.perf_counter()
        counts = zoom.manage(batch, stamp=stamp)
        ended = time.perf_counter()
        zoom_times.append(ended - started)
        if moved:
            moves_s.append(between - started)
        managed.append(len(zoom.rows))
        for key, value in counts.items():
            zoom_counts[key] = zoom_counts.get(key, 0) + value
    return {
        "objects": objects,
        "updates": updates,
        "perceptions_per_update": float(np.mean([len(b) for b in seen])),
        "full_ms": 1000 * float(np.mean(full_times)),
        "zoom_ms": 1000 * float(np.mean(zoom_times)),
        "full_max_ms": 1000 * float(np.max(full_times)),
        "zoom_max_ms": 1000 * float(np.max(zoom_times)),
        "zoom_managed_mean": float(np.mean(managed)),
        "zoom_managed_max": int(np.max(managed)),
        "zoom_moves": len(zoom.history),
        "zoom_move_ms": 1000 * float(np.mean(moves_s)) if moves_s else 0.0,
        "zoom_area_m2": float(np.mean([m.width * m.depth for m in zoom.history])),
        "full_counts": full_counts,
        "zoom_counts": zoom_counts,
    }


def fit(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Least-squares fits of eq. 6.1 (full) and eq. 6.2 (zoom) against the measures (ms per update)."""
    np_ = np.array([r["perceptions_per_update"] for r in rows])
    full_x = np_ * np.array([r["objects"] for r in rows], dtype=float)
    zoom_x = np_ * np.array([r["zoom_managed_mean"] for r in rows])
    full_y = np.array([r["full_ms"] for r in rows])
    full_b, full_a = np.polyfit(full_x, full_y, 1, w=1 / full_y)  # relative residuals: every size counts
    move_share = np.array([r["zoom_move_ms"] * r["zoom_moves"] / r["updates"] for r in rows])
    zoom_y = np.array([r["zoom_ms"] for r in rows]) - move_share
    zoom_b, zoom_a = np.polyfit(zoom_x, zoom_y, 1, w=1 / np.maximum(zoom_y, 1e-6))
    for row, fx, zx, share in zip(rows, full_x, zoom_x, move_share, strict=True):
        row["full_model_ms"] = float(full_a + full_b * fx)
        row["zoom_model_ms"] = float(zoom_a + zoom_b * zx + share)
    return {
        "full": {"a_ms": float(full_a), "b_ns_per_comparison": float(full_b * 1e6)},
        "zoom": {"a_ms": float(zoom_a), "b_ns_per_comparison": float(zoom_b * 1e6)},
    }


def run(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Time full and zoom map management per object count (eq. 6.1/6.2, §6.1.3), fit them, draw the figures."""
    parser = argparse.ArgumentParser(prog="ckm-bench zoom", description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(DEFAULT_SIZES), help="object counts")
    parser.add_argument("--updates", type=int, default=400, help="perception updates per size (10 per second)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("runs/bench-zoom"), help="where the figures go")
    args = parser.parse_args(list(argv or []))
    if any(n < 1 for n in args.sizes) or args.updates < 2:
        parser.error("sizes must be positive and updates at least 2")
    rows = [measure(n, args.updates, args.seed) for n in sorted(args.sizes)]
    model = fit(rows) if len(rows) >= 2 else None
    args.out.mkdir(parents=True, exist_ok=True)
    tour = lab_tour(args.out / "zoom_areas.png")
    time_plot(rows, args.out / "zoom_times.png")
    return {
        "sizes": rows,
        "model": model,
        "zoom": {"mode": ZOOM.mode, "width": ZOOM.width, "depth": ZOOM.depth, "max_objects": ZOOM.max_objects},
        "floor_m": SIDE,
        "lab_tour": tour,
        "figures": [str(args.out / "zoom_areas.png"), str(args.out / "zoom_times.png")],
    }


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench zoom``'s table."""
    rows = []
    for row in result["sizes"]:
        label = f"{row['objects']:>7} objects: full / zoom (managed)"
        model = ""
        if "full_model_ms" in row:
            model = f"  [eq. 6.1/6.2: {row['full_model_ms']:.3f} / {row['zoom_model_ms']:.3f}]"
        rows.append(
            (label, f"{row['full_ms']:.3f} / {row['zoom_ms']:.3f} ms ({row['zoom_managed_mean']:.0f}){model}")
        )
    tour = result["lab_tour"]
    rows.append(("lab tour: goals / zoom moves", f"{tour['goals']} / {len(tour['moves'])}"))
    rows.append(("figures", ", ".join(result["figures"])))
    return rows


def lab_tour(png: Path) -> dict[str, Any]:
    """The §7.4.1 experiment on the use-case lab with its own ``<ZoomMap>``; draws Fig. 7.16 to ``png``."""
    env = ckmconf.load(LAB).environment
    assert env is not None and env.zoom is not None
    model = MapModel.from_environment(env)
    zoom = ZoomMap.of(model, env.zoom)
    tour = drive(model, zoom, LAB_GOALS)
    draw_tour(model, tour, LAB_GOALS, png)
    return {
        "goals": len(LAB_GOALS) - 1,
        "length_m": sum(math.dist(a, b) for a, b in zip(tour.positions, tour.positions[1:], strict=False)),
        "moves": [
            {"t": round(m.time, 2), "reason": m.reason, "x": round(m.x, 3), "y": round(m.y, 3), "objects": m.objects}
            for m in tour.moves
        ],
    }


def time_plot(rows: list[dict[str, Any]], png: Path) -> None:
    """Milliseconds per perception update against the number of objects, measures and eq. 6.1/6.2 fits."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = [r["objects"] for r in rows]
    figure, axes = plt.subplots(figsize=(7, 4.5))
    axes.loglog(sizes, [r["full_ms"] for r in rows], "o-", label="full map (measured)")
    axes.loglog(sizes, [r["zoom_ms"] for r in rows], "s-", label="zoom map (measured)")
    if "full_model_ms" in rows[0]:
        axes.loglog(sizes, [max(r["full_model_ms"], 1e-4) for r in rows], "k:", label="eq. 6.1 fit")
        axes.loglog(sizes, [max(r["zoom_model_ms"], 1e-4) for r in rows], "k--", label="eq. 6.2 fit")
    axes.set_xlabel("objects in the map")
    axes.set_ylabel("ms per perception update")
    axes.set_title("Map management time per perception update")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend()
    figure.tight_layout()
    figure.savefig(png, dpi=110)
    plt.close(figure)
