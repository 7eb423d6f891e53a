"""Perceptions into the map (thesis §6.1.1, §6.1.3 eq. 6.1–6.2, §6.3 output).

:func:`manage` is the map-management step of eq. 6.1/6.2: every perception ``p_j`` is compared
with every managed map element ``m_k`` (``f(p_j, m_k)``, here the squared distance between
centres, vectorised with numpy), matched to the nearest one within a gate, and the map is
updated; an unmatched perception becomes a new object. With ``rows=None`` the managed elements
are the whole map (eq. 6.1); a zoom map passes its own rows (eq. 6.2).

:func:`ingest_fused` takes the output of the fusion service (``plugin.feature-fusion``:
``{"objects": [{"name", "shape", "texture", "x", "y", "z", "reliability", …}], …}``) and
enters each positioned object into the map with its reliability.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .map_model import MapModel, small_object


def associate(model: MapModel, perceptions: np.ndarray, rows: np.ndarray | None, gate: float) -> np.ndarray:
    """For each perception (``np × 2`` array), the map row of its nearest managed element within ``gate``, or -1."""
    if len(perceptions) == 0:
        return np.zeros(0, dtype=np.int64)
    elements = model.xy if rows is None else model.xy[rows]
    if len(elements) == 0:
        return np.full(len(perceptions), -1, dtype=np.int64)
    d2 = ((perceptions[:, None, :] - elements[None, :, :]) ** 2).sum(axis=2)  # f(p_j, m_k) for all j, k
    best = d2.argmin(axis=1)
    hit = d2[np.arange(len(perceptions)), best] <= gate * gate
    found = best if rows is None else rows[best]
    return np.where(hit, found, -1)


def manage(
    model: MapModel,
    perceptions: np.ndarray,
    *,
    stamp: float,
    rows: np.ndarray | None = None,
    gate: float = 0.3,
    tag: str = "unknown",
    reliability: float | None = None,
    source: str = "perception",
) -> dict[str, int]:
    """One map-management step (eq. 6.1 with ``rows=None``, the zoom map's t'_i otherwise).

    Returns how many perceptions were ``confirmed``, ``moved``, ``added``, ``stale`` or ``refused``.
    """
    counts = dict.fromkeys(("confirmed", "moved", "added", "stale", "refused"), 0)
    matches = associate(model, perceptions, rows, gate)
    for (x, y), row in zip(perceptions.tolist(), matches.tolist(), strict=True):
        if row < 0:
            name = fresh_name(model, tag)
            model.add(small_object(name, tag, x, y, stamp=stamp, source=source, reliability=reliability or 1.0))
            counts["added"] += 1
        else:
            outcome = model.observe(model.names[row], x, y, stamp=stamp, reliability=reliability, source=source)
            counts[outcome] += 1
    return counts


def fresh_name(model: MapModel, base: str) -> str:
    """``base-N`` with N the map's size, counting up past names already taken."""
    number = len(model)
    while f"{base}-{number}" in model:
        number += 1
    return f"{base}-{number}"


def _to_map(frame: tuple[float, float, float, float], x: float, y: float, z: float) -> tuple[float, float, float]:
    fx, fy, fz, yaw = frame
    c, s = math.cos(yaw), math.sin(yaw)
    return fx + c * x - s * y, fy + s * x + c * y, fz + z


def ingest_fused(
    model: MapModel,
    result: Mapping[str, Any],
    *,
    stamp: float,
    frame: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0),
    gate: float = 0.3,
    source: str = "fusion",
    suffix: str = "",
) -> list[tuple[str, str]]:
    """Enter the fusion service's recognised objects into the map; ``(map object, outcome)`` per object.

    ``frame`` is the pose ``(x, y, z, yaw)`` in the map of the fusion's common frame (z up).
    Objects without a position (a lone 2D ray) are skipped. A recognised name already in the
    map updates that object; a shape class (``cylinder``) updates the nearest object of that tag
    within ``gate``; anything else is added, tagged with its shape, with its reliability, named
    ``name{suffix}-N`` (a robot's map service puts ``@robot`` there: two robots' new objects never
    share a name, so newer-wins merging never fuses two different objects).
    """
    outcomes = []
    for item in result.get("objects", ()):
        if not isinstance(item, Mapping) or item.get("x") is None:
            continue
        x, y, z = _to_map(frame, float(item["x"]), float(item["y"]), float(item.get("z") or 0.0))
        reliability = float(item.get("reliability", 1.0))
        name, shape = str(item.get("name")), item.get("shape")
        target = name if name in model else None
        if target is None:
            nearest = model.nearest(x, y, 1, tag=str(shape or name), max_distance=gate)
            target = nearest[0][1].name if nearest else None
        if target is not None:
            outcome = model.observe(target, x, y, z=z, stamp=stamp, reliability=reliability, source=source)
            outcomes.append((target, outcome))
            continue
        new = fresh_name(model, name + suffix)
        tag = str(shape or name)
        model.add(small_object(new, tag, x, y, z=z, stamp=stamp, reliability=reliability, source=source,
                               texture=item.get("texture")))
        outcomes.append((new, "added"))
    return outcomes
