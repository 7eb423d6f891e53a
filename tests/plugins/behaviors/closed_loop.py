"""What the behaviors' closed-loop tests share: the navigation bench's services as a behavior sees them.

The bench (tests/plugins/navigation/loop.py) runs the real laser-scan, base-displacement and
amcl-navigation services on a robot model in the pybullet world. :class:`BenchNavigation` is its
navigation service as a behavior's handle; :class:`SightDetector` stands in for an object-detection
service (the bench has no camera): it reports each listed object within ``reach`` metres and
``half_fov`` radians of the robot's true heading, relative to the robot, as a detector reports what
its sensor sees (``{objects: [{name, x, y, z, reliability}]}``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from runtime.resources.api import Bounds
from tests.plugins.navigation.loop import Bench


class BenchNavigation:
    """The bench's Navigation plugin as a behavior sees a navigation service (configure, outputs)."""

    def __init__(self, bench: Bench) -> None:
        self.bench, self.ref = bench, "Navigation.AMCL"
        self.plugin = bench.services["nav"].plugin

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        self.plugin.apply_service_parameters(dict(parameters))  # type: ignore[attr-defined]

    def output(self, name: str) -> Any:
        return self.bench.latest({"status": "/nav/status", "pose": "/nav/pose"}[name])

    def measures(self) -> dict[str, float]:
        return {}

    def samples(self, measure: str) -> list[float]:
        return []

    def running(self) -> bool:
        return True


class SightDetector:
    """An object-detection service seeing ``objects`` (name → (x, y) on the map) from the robot's true pose."""

    def __init__(self, bench: Bench, objects: Mapping[str, tuple[float, float]], *, reach: float = 1.4,
                 half_fov: float = 0.5, reliability: float = 0.9) -> None:
        self.bench, self.ref = bench, "Camera.Detect"
        self.objects, self.reach, self.half_fov, self.reliability = dict(objects), reach, half_fov, reliability
        self.sightings: list[str] = []

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        return None

    def output(self, name: str) -> Any:
        assert name == "objects"
        x, y, yaw = self.bench.truth()
        seen = []
        for label, (ox, oy) in self.objects.items():
            dx, dy = ox - x, oy - y
            ahead, left = math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy
            if math.hypot(dx, dy) <= self.reach and abs(math.atan2(left, ahead)) <= self.half_fov:
                seen.append({"name": label, "x": ahead, "y": left, "z": 0.1, "reliability": self.reliability})
                self.sightings.append(label)
        return {"objects": seen, "reliability": self.reliability if seen else 0.0}

    def measures(self) -> dict[str, float]:
        return {}

    def samples(self, measure: str) -> list[float]:
        return []

    def running(self) -> bool:
        return True
