"""The delay-free measure (§3.1.2.1): a sensor's value estimated at the controller's instant.

Acquisition happens at the sensor's period, control at the controller's; between the two the
measure ages. Extrapolating from the last samples to the control instant removes that delay
from the loop: ``hold`` keeps the last value, ``linear`` follows the last two, ``quadratic`` fits
the last three. ``none`` means no estimate: the last value as measured.
"""

from __future__ import annotations

from collections.abc import Sequence


def extrapolate(samples: Sequence[tuple[float, float]], at: float, method: str) -> float:
    """Value at time ``at`` from ``(time, value)`` samples, oldest first (at least one)."""
    if not samples:
        raise ValueError("no samples to extrapolate from")
    t2, v2 = samples[-1]
    if method in ("none", "hold") or len(samples) < 2:
        return v2
    t1, v1 = samples[-2]
    if method == "linear" or len(samples) < 3 or t2 == t1:
        return v2 if t2 == t1 else v2 + (v2 - v1) * (at - t2) / (t2 - t1)
    t0, v0 = samples[-3]
    if len({t0, t1, t2}) < 3:
        return v2 + (v2 - v1) * (at - t2) / (t2 - t1)
    # Lagrange form of the parabola through the last three samples.
    return (
        v0 * (at - t1) * (at - t2) / ((t0 - t1) * (t0 - t2))
        + v1 * (at - t0) * (at - t2) / ((t1 - t0) * (t1 - t2))
        + v2 * (at - t0) * (at - t1) / ((t2 - t0) * (t2 - t1))
    )
