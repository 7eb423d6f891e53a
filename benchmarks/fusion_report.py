"""Figures and table of ``ckm-bench fusion`` (Fig. 7.18, 7.19): statistics of the scored observations, plots."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from plugins.processing.fusion_model import share_at_bound

METHODS = ("depth", "rgb", "fused")
NEAR_BOUND = 0.999
"""Fused values at or above this are reported as "near the bound" (the last thousandth)."""


def _stats(values: Sequence[float]) -> dict[str, float | None]:
    if not values:
        return {"mean": None, "std": None}
    return {"mean": round(float(np.mean(values)), 4), "std": round(float(np.std(values)), 4)}


def _shape(name: str) -> str:
    """The shape an object's name starts with (the catalogue names ``shape_print``)."""
    return name.split("_")[0]


def usable(hit: tuple[float, str, bool] | None, name: str) -> bool:
    """A result about the object that is not wrong: right, or a fused object named by its shape only."""
    return hit is not None and (hit[2] or hit[1] == _shape(name))


def _method(name: str, rows: list[dict[str, Any]], method: str) -> dict[str, Any]:
    hits = [row[method] for row in rows if row[method] is not None]
    right = [h for h in hits if h[2]]
    return {
        "detected": round(len(hits) / len(rows), 4) if rows else 0.0,
        "accuracy": round(len(right) / len(hits), 4) if hits else None,
        "recall": round(len(right) / len(rows), 4) if rows else 0.0,
        **_stats([row[method][0] for row in rows if usable(row[method], name)]),
    }


def _object(name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    entry: dict[str, Any] = {"name": name, "observations": len(rows)}
    entry |= {method: _method(name, rows, method) for method in METHODS}
    fused = [row["fused"][0] for row in rows if row["fused"] is not None]
    entry["fused_at_bound"] = round(share_at_bound(fused), 4)
    entry["fused_near_bound"] = round(share_at_bound(fused, bound=NEAR_BOUND, tolerance=0.0), 4)
    errors = [row["fused_error"] for row in rows if row["fused"] is not None and row.get("fused_error") is not None]
    entry["fused_error_m"] = _stats(errors)
    both = [row for row in rows if row["fused"] is not None and row.get("fused_sources") == ["depth", "rgb"]]
    entry["fused_both"] = round(len(both) / len(rows), 4) if rows else 0.0
    # Same-shape discrimination: fused objects named by a texture (not the bare shape): the right one?
    family = f"{_shape(name)}_"
    named = [row["fused"] for row in rows if row["fused"] is not None and row["fused"][1].startswith(family)]
    entry["discrimination"] = round(sum(h[2] for h in named) / len(named), 4) if named else None
    paired = [row for row in both if row["depth"] is not None and row["rgb"] is not None]
    entry["paired"] = {"views": len(paired)} | {
        method: _stats([row[method][0] for row in paired]) for method in METHODS
    }
    # The targets (reported, not asserted) on the views where both inputs saw the object and fused.
    means = {m: entry["paired"][m]["mean"] for m in METHODS}
    spreads = {m: entry["paired"][m]["std"] for m in METHODS}
    singles = [m for m in ("depth", "rgb") if means[m] is not None]
    entry["fused_mean_above"] = bool(
        means["fused"] is not None and singles and all(means["fused"] > means[m] for m in singles)
    )
    entry["fused_spread_below"] = bool(
        spreads["fused"] is not None and singles and all(spreads["fused"] < spreads[m] for m in singles)
    )
    return entry


def summarise(scored: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """Per-object statistics (Fig. 7.18), and the cylinders' discrimination taken together."""
    objects = [_object(name, rows) for name, rows in scored.items()]
    cylinders = [
        row["fused"]
        for name, rows in scored.items()
        if name.startswith("cylinder_")
        for row in rows
        if row["fused"] is not None and row["fused"][1].startswith("cylinder_")
    ]
    fused = [row["fused"][0] for rows in scored.values() for row in rows if row["fused"] is not None]
    return {
        "objects": objects,
        "discrimination_cylinders": round(sum(h[2] for h in cylinders) / len(cylinders), 4) if cylinders else None,
        "fused_at_bound": round(share_at_bound(fused), 4),
        "fused_near_bound": round(share_at_bound(fused, bound=NEAR_BOUND, tolerance=0.0), 4),
    }


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """Table rows: per object and method, then the cylinders' discrimination, the bound and the cost."""
    rows = []
    for obj in result["objects"]:
        for method in METHODS:
            m = obj[method]
            rows.append(
                (
                    f"{obj['name']} {method}",
                    f"r {_fmt(m['mean'])} ± {_fmt(m['std'])}, detected {m['detected']:.0%}, "
                    f"accuracy {_fmt(m['accuracy'], 3)}, recall {m['recall']:.0%}",
                )
            )
        rows.append(
            (
                f"{obj['name']} fused: both inputs / discrimination",
                f"{obj['fused_both']:.0%} / {_fmt(obj['discrimination'])}, "
                f"error {_fmt(obj['fused_error_m']['mean'])} m, "
                f"at 1.0 {obj['fused_at_bound']:.1%}, ≥{NEAR_BOUND} {obj['fused_near_bound']:.1%}, "
                f"paired views {obj['paired']['views']}: mean above {obj['fused_mean_above']}, "
                f"spread below {obj['fused_spread_below']}",
            )
        )
    rows.append(("cylinders told apart (fused, by texture)", _fmt(result["discrimination_cylinders"])))
    rows.append(("fused values at 1.0 / ≥ 0.999", f"{result['fused_at_bound']:.1%} / {result['fused_near_bound']:.1%}"))
    track = result["approach"]["track"]
    last = track[-1]
    rows.append(
        (
            f"approach to {result['approach']['object']} (Fig. 7.19), at {last['distance']:.2f} m",
            ", ".join(f"{m} {last[m]:.3f}" for m in METHODS),
        )
    )
    rows.append(("renders, time", f"{result['renders']} in {result['seconds']} s ({result['ms_per_render']} ms each)"))
    rows.append(("plots", ", ".join(result["plots"])))
    return rows


def plot_reliability(scored: dict[str, list[dict[str, Any]]], png: Path) -> None:
    """Fig. 7.18: per object, box plots of the depth, RGB and fused reliabilities (results not wrong)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(scored)
    figure, axes = plt.subplots(1, len(names), figsize=(3.0 * len(names), 3.6), sharey=True)
    for ax, name in zip(np.atleast_1d(axes), names, strict=True):
        data = [[row[m][0] for row in scored[name] if usable(row[m], name)] for m in METHODS]
        shown = [d if d else [np.nan] for d in data]
        ax.boxplot(shown, showfliers=True, flierprops={"markersize": 2})
        ax.set_xticks(range(1, len(METHODS) + 1), ["depth", "RGB", "fused"])
        ax.set_title(name.replace("_", " "), fontsize=9)
        ax.set_ylim(0.0, 1.02)
        ax.grid(axis="y", alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("reliability")
    figure.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=100)
    plt.close(figure)


def plot_approach(track: list[dict[str, Any]], name: str, png: Path) -> None:
    """Fig. 7.19: reliability (top), distance (middle) and angle (bottom) along the approach."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [row["step"] for row in track]
    figure, axes = plt.subplots(3, 1, figsize=(7, 6.5), sharex=True)
    for method, style in zip(METHODS, ("s-", "^-", "o-"), strict=True):
        axes[0].plot(steps, [row[method] for row in track], style, markersize=3, label=method)
    axes[0].set_ylabel("reliability")
    axes[0].set_ylim(0.0, 1.05)
    axes[0].legend(fontsize=8, loc="lower right")
    axes[0].set_title(f"approach to {name.replace('_', ' ')}", fontsize=9)
    axes[1].plot(steps, [row["distance"] for row in track], "k-")
    axes[1].axhline(0.6, color="grey", linestyle=":")
    axes[1].set_ylabel("distance (m)")
    axes[2].plot(steps, [row["angle"] for row in track], "k-")
    axes[2].axhline(0.0, color="grey", linestyle=":")
    axes[2].set_ylabel("angle (rad)")
    axes[2].set_xlabel("step")
    for ax in axes:
        ax.grid(alpha=0.3)
    figure.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=100)
    plt.close(figure)
