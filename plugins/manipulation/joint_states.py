"""Reading a JointState (sensor_msgs/JointState: ``{stamp, name, position, velocity?, effort?}``) for
the manipulation services: the positions (and efforts) of the joints a service moves, in the order
of its Param ``joints``; a JointState without names (as an arm's bus sensor publishes it, D99) is
taken in that order: its leading positions, as ``controller.joint-trajectory`` takes them, so one bus of
a robot's joints (a lift, then a clamp's pad) serves a service of the first of them (D303)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any


def _numbers(values: Any, field: str, owner: str) -> list[float]:
    try:
        return [float(q) for q in values]
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: joint_states {field!r} is not a list of numbers") from None


def joint_values(state: Any, joints: Sequence[str], owner: str, field: str = "position") -> list[float] | None:
    """``field`` of each of ``joints`` in the JointState ``state``; None before the first state (or,
    for ``effort``/``velocity``, when the state carries none).

    Raises:
        ValueError: ``state`` is not a JointState, lacks a joint, or holds a value that is not finite.
    """
    if state is None:
        return None
    if not isinstance(state, Mapping) or "position" not in state:
        raise ValueError(f"{owner}: joint_states is not a JointState (no 'position')")
    raw = state.get(field)
    if field != "position" and (raw is None or len(raw) == 0):
        return None
    values = _numbers(raw, field, owner)
    names = [str(n) for n in (state.get("name") or [])]
    if names:
        if len(names) != len(values):
            raise ValueError(f"{owner}: joint_states has {len(names)} names for {len(values)} {field}s")
        by_name = dict(zip(names, values, strict=True))
        missing = [j for j in joints if j not in by_name]
        if missing:
            raise ValueError(f"{owner}: joint_states has no {', '.join(missing)}")
        values = [by_name[j] for j in joints]
    elif len(values) < len(joints):
        raise ValueError(f"{owner}: joint_states has {len(values)} unnamed {field}s, expected "
                         f"{len(joints)} ({' '.join(joints)})")
    else:
        values = values[: len(joints)]
    if not all(math.isfinite(q) for q in values):
        raise ValueError(f"{owner}: joint_states holds a {field} that is not finite")
    return values
