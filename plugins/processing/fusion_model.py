"""Pieces of the feature fusion (thesis §6.3.2–6.3.3) shared by ``plugin.feature-fusion`` and its benchmark.

- :class:`Observation`: S(θ)ᵢ of eq. 6.35, one recognised object of one input in the common frame;
- :func:`reinforce`: eq. 6.41's reinforcement of the reliability by one matched observation;
- :func:`share_at_bound`: how many fused reliabilities sit at the upper bound;
- :func:`fused_object`: f̂ and r̂ of eq. 6.39 as the service's output record, with the centre its
  most reliable 3D observation gave (D253);
- :func:`number`: one finite number of an input message.

The per-input Params (``"name: v1 v2; name: v…"``) are declared with
:class:`runtime.verification.entries.Entries` and reach the plugin parsed (D184).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .geometry import Geometry, Point


@dataclass
class Observation:
    """S(θ)ᵢ of eq. 6.35: one recognised object of one input, placed in the common frame."""

    source: str
    index: int
    model: str
    reliability: float
    geometry: Geometry
    magnitude: str
    knowledge: dict[str, str] = field(default_factory=dict)


def number(value: Any, bad: Callable[[str, str], ValueError], where: str) -> float:
    """A finite number of an input message (not a bool), or ``bad(where, why)``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise bad(where, f"is not a number: {value!r}")
    if not math.isfinite(float(value)):
        raise bad(where, f"is not finite: {value!r}")
    return float(value)


def reinforce(reliability: float, support: float) -> float:
    """Eq. 6.41 kept in [0, 1] (D74): the support adds as a probabilistic sum, r + s·(1 − r)."""
    return reliability + support * (1.0 - reliability)


def share_at_bound(reliabilities: Iterable[float], bound: float = 1.0, tolerance: float = 1e-9) -> float:
    """The share of fused reliabilities at the upper bound (within ``tolerance``); 0 for none.

    A fused reliability that saturates says nothing about the observations any more: Fig. 7.18
    compares spreads, which a value stuck at the bound hides (``ckm-bench fusion`` reports it).
    """
    values = np.asarray(list(reliabilities), dtype=np.float64)
    if values.size == 0:
        return 0.0
    return float(np.count_nonzero(values >= bound - tolerance)) / values.size


def fused_object(
    model: str,
    knowledge: dict[str, str],
    theta: Geometry,
    r_hat: float,
    raw: float,
    members: list[Observation],
    frame: str,
) -> dict[str, Any]:
    """f̂ and r̂ of eq. 6.39 as a msgpack-able dict, placed in ``frame``.

    ``centre`` is the point of the most reliable 3D member as its service gave it (the solid's centre
    a shape fit finds), None without one: a fused θ̂ leans towards a joined ray, which passes through
    the print's keypoints on the surface, not through the axis a grasp needs (D253)."""
    place: dict[str, Any] = dict.fromkeys(("x", "y", "z", "sigma", "origin", "direction", "centre"))
    if isinstance(theta, Point):
        x, y, z = (float(v) for v in theta.mean)
        place |= {"x": x, "y": y, "z": z, "sigma": math.sqrt(float(np.trace(theta.cov)) / 3.0)}
    else:
        place |= {"origin": [float(v) for v in theta.origin], "direction": [float(v) for v in theta.direction]}
    point = next((m.geometry for m in members if isinstance(m.geometry, Point)), None)
    if point is not None:
        place["centre"] = [float(v) for v in point.mean]
    return {
        "name": knowledge.get("object", model),
        "shape": knowledge.get("shape"),
        "texture": knowledge.get("texture"),
        **place,
        "frame": frame,
        "reliability": r_hat,
        "reinforcement": raw,
        "sources": [m.source for m in members],
        "observations": len(members),
    }
