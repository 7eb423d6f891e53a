"""What the behaviors' closed-loop tests share: the navigation bench's services as a behavior sees them.

The bench (tests/plugins/navigation/loop.py) runs the real laser-scan, base-displacement and
amcl-navigation services on a robot model in the pybullet world. :class:`BenchNavigation` and
:class:`BenchBase` are its navigation and base-drive services as a behavior's handles; :func:`wired`
builds a behavior on them and on bench topics, :func:`run_states` steps behaviors as the mission engine
does; :class:`SightDetector` stands in for an object-detection
service (the bench has no camera): it reports each listed object within ``reach`` metres and
``half_fov`` radians of the robot's true heading, relative to the robot, as a detector reports what
its sensor sees (``{objects: [{name, x, y, z, reliability}]}``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorInput, BehaviorOutput, Configure, Uses
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.resources.api import Bounds
from tests.plugins.navigation.loop import Bench


class OutputsService:
    """A service handle that reads its outputs with ``read(name)`` and hands Parameters to ``configure``."""

    def __init__(self, ref: str, read: Callable[[str], Any],
                 configure: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.ref, self._read, self._configure = ref, read, configure

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        if self._configure is not None:
            self._configure(dict(parameters))

    def output(self, name: str) -> Any:
        return self._read(name)

    def measures(self) -> dict[str, float]:
        return {}

    def samples(self, measure: str) -> list[float]:
        return []

    def running(self) -> bool:
        return True


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


class BenchBase:
    """The bench's base-drive service as a behavior sees it: its ``move_status`` and ``odom`` outputs."""

    def __init__(self, bench: Bench) -> None:
        self.bench, self.ref = bench, "MobileBase.Displacement"

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        return None

    def output(self, name: str) -> Any:
        return self.bench.latest({"move_status": "/base/move_status", "odom": "/base/odom"}[name])

    def measures(self) -> dict[str, float]:
        return {}

    def samples(self, measure: str) -> list[float]:
        return []

    def running(self) -> bool:
        return True


def wired(bench: Bench, cls: type[Behavior], name: str, services: Mapping[str, Any] | None = None,
          inputs: Mapping[str, str] | None = None, outputs: Mapping[str, str] | None = None, *,
          configure: Mapping[str, Mapping[str, str]] | None = None, **params: str) -> Behavior:
    """The behavior ``cls`` using ``services`` (alias → handle; ``configure`` gives an alias's
    ``<Configure>`` Parameters), its inputs and outputs on bench topics (name → topic), its arrival
    counts the topics' sequence numbers."""
    services, inputs, outputs = dict(services or {}), dict(inputs or {}), dict(outputs or {})
    given = configure or {}
    uses = tuple(Uses(service=handle.ref, as_=alias,
                      configure=tuple(Configure(parameter=k, value=v) for k, v in given.get(alias, {}).items()))
                 for alias, handle in services.items())
    record = BehaviorRecord(name=name, kind="-", timeout=120.0, uses=uses,
                            params=tuple(Param(name=k, value=v) for k, v in params.items()),
                            inputs=tuple(BehaviorInput(name=n, topic=t) for n, t in inputs.items()),
                            outputs=tuple(BehaviorOutput(name=n, topic=t) for n, t in outputs.items()))

    def heard(topic: str) -> int:
        return bench.topics[topic][0] if topic in bench.topics else 0

    context = BehaviorContext(
        services=services, now=lambda: bench.now,
        inputs={n: functools.partial(bench.latest, t) for n, t in inputs.items()},
        heard={n: functools.partial(heard, t) for n, t in inputs.items()},
        outputs={n: functools.partial(bench.publish, t) for n, t in outputs.items()},
    )  # fmt: skip
    return cls(record, context)


def run_states(bench: Bench, states: list[Behavior], timeout: float) -> list[tuple[str, BehaviorStatus]]:
    """Step ``states`` one after the other at every physics step until the last is done or one fails."""
    pending = list(states)
    pending[0].start()
    statuses: list[tuple[str, BehaviorStatus]] = []

    def ended() -> bool:
        status = pending[0].step()
        statuses.append((pending[0].name, status))
        if status.failed:
            return True
        if status.done:
            pending.pop(0)
            if not pending:
                return True
            pending[0].start()
        return False

    assert bench.run(ended, timeout), f"not ended: {statuses[-1]}, at {bench.truth()}"
    return statuses


def angle(a: float, b: float) -> float:
    """|a − b| wrapped to [0, π] (rad)."""
    return abs(math.atan2(math.sin(a - b), math.cos(a - b)))
