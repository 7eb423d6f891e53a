"""What the Navigation service publishes for the live view and the recording (issue K.5; §6.1.3,
§6.2.1 Algorithm 3, Fig. 7.16).

- :func:`particle_cloud`: a ``ParticleCloud`` message (its MessageType declared by the system) of at most
  ``size`` of the filter's particles, evenly strided through its set (no random draw: the filter's
  generator, whose state a delegated copy carries on, is left alone), as parallel arrays ``x``,
  ``y``, ``yaw`` and ``weight`` (a ROS-friendly shape: each a ``float64[]`` in the recording) with
  ``total``, the filter's particle count. The weight is the filter's normalised one: the AMCL-like
  baseline keeps per-particle weights; Algorithm 3 leaves every particle equal after it replaces
  the weak ones (lines 16-19), so each weighs 1/total.
- :class:`NavigationZoom`: the Zoom Map (§6.1.3, plugins/environment/zoom.py) of the
  ``<Environment>``'s ``<ZoomMap>`` over the Navigation's own map model, re-centred on the
  estimate by the ``<ZoomMap>`` rules (the first estimate, the border, the timeout). Its
  ``ZoomArea`` message is the area it holds now: centre, size, mode, why and when it last moved,
  and the objects and avoided areas it manages (what is around the robot, §7.4.1).

Both cost little at the service's rate: a strided copy of ≤ ``size`` rows, a rectangle test and,
only when the area moves, one STRtree query (decision D215).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ckmconf.model.environment import ZoomMap as ZoomRecord
from plugins.environment.map_model import MapModel
from plugins.environment.zoom import ZoomMap
from plugins.localization.mcl import AmclFilter
from plugins.localization.reliability_filter import ReliabilityFilter

FRAME = "map"


def particle_cloud(particle_filter: AmclFilter | ReliabilityFilter, size: int, stamp: float) -> dict[str, Any] | None:
    """The ParticleCloud message of ≤ ``size`` particles of ``particle_filter`` (None: ``size`` 0 or no particles)."""
    particles = np.asarray(particle_filter.particles, dtype=np.float64)
    total = len(particles)
    if size <= 0 or total == 0:
        return None
    index = np.unique(np.linspace(0, total - 1, min(size, total)).round().astype(np.intp))
    chosen = particles[index]
    if isinstance(particle_filter, AmclFilter) and len(particle_filter.weights) == total:
        weight = np.asarray(particle_filter.weights, dtype=np.float64)[index]
    else:
        weight = np.full(len(index), 1.0 / total)
    yaw = (chosen[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return {"stamp": float(stamp), "frame": FRAME, "total": int(total), "x": chosen[:, 0].copy(),
            "y": chosen[:, 1].copy(), "yaw": yaw, "weight": weight}  # fmt: skip


class NavigationZoom:
    """The Navigation's Zoom Map (§6.1.3) following its estimate; see the module docstring."""

    def __init__(self, model: MapModel, record: ZoomRecord) -> None:
        self.zoom = ZoomMap.of(model, record)

    def update(self, x: float, y: float, now: float) -> dict[str, Any]:
        """Move the area if the ``<ZoomMap>`` rules say so for the robot at ``(x, y)``; the ZoomArea message."""
        self.zoom.update(x, y, now)
        return self.message(now)

    def message(self, stamp: float) -> dict[str, Any]:
        """The area the zoom map holds now (after a first :meth:`update`)."""
        current = self.zoom.current
        if current is None:
            raise RuntimeError("the zoom map has no area before its first update")
        s = self.zoom.settings
        return {"stamp": float(stamp), "frame": FRAME, "mode": s.mode, "x": current.x, "y": current.y,
                "width": current.width, "depth": current.depth, "height": s.height, "reason": current.reason,
                "since": current.time, "objects": [o.name for o in self.zoom.objects],
                "avoided": self.zoom.avoided()}  # fmt: skip

    def state(self) -> dict[str, Any] | None:
        """The current area's move (codec-able), for a delegated copy."""
        current = self.zoom.current
        return None if current is None else {"x": current.x, "y": current.y, "time": current.time,
                                             "reason": current.reason}  # fmt: skip

    def restore(self, state: Mapping[str, Any] | None) -> None:
        """Go on from :meth:`state`: the same centre, moved at the same time (its size and objects follow)."""
        self.zoom.history.clear()
        if state is not None:
            self.zoom.recentre(float(state["x"]), float(state["y"]), float(state["time"]), str(state["reason"]))
