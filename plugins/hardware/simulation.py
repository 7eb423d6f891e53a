"""Simulated time and isolation, shared by the simulated backends (loopback now, pybullet later).

- A clock is any ``() -> float`` in seconds: ``time.monotonic`` for real time, a
  :class:`ManualClock` for tests and lock-step simulation.
- A :class:`PlantScope` is an isolation domain, compared by identity, that carries the clock: a
  backend keys its shared simulated world by (scope, name), so two nodes, two runs of a node in one
  process or two tests never share a world. A backend takes its scope, when built, from its
  ``scope`` argument, else the innermost ``with plant_scope(…)`` block (the node builder wraps the
  construction of a node's backends in one), else :func:`scope_for`'s scope per (configuration
  file, node path) of the channel record, which is right for one node per process.
- A :class:`SimulationHook` is a simulated world advanced lazily to its clock's time whenever a
  channel touches it: the loopback plant integrates its equation there; the pybullet backend will
  step its physics engine.
"""

from __future__ import annotations

import abc
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from ckmconf.model import HWChannel

Clock = Callable[[], float]


class ManualClock:
    """A clock that moves only when told to: for tests, and for simulators run in lock-step."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        """The current time in seconds (what a clock is called for)."""
        return self.now

    def advance(self, seconds: float) -> float:
        """Move time forward by ``seconds``; returns the new time."""
        if seconds < 0.0:
            raise ValueError("time cannot go backwards")
        self.now += seconds
        return self.now


class PlantScope:
    """An isolation domain for simulated plants (compared by identity) and their clock."""

    def __init__(self, clock: Clock = time.monotonic, name: str = "") -> None:
        self.clock = clock
        self.name = name

    def __repr__(self) -> str:
        return f"PlantScope({self.name or hex(id(self))})"


_current_scope: ContextVar[PlantScope | None] = ContextVar("ckm_plant_scope", default=None)
_node_scopes: dict[tuple[str, str], PlantScope] = {}
_scopes_lock = threading.Lock()


@contextmanager
def plant_scope(scope: PlantScope | None = None) -> Iterator[PlantScope]:
    """Backends built inside the block use ``scope`` (a new one by default)."""
    scope = scope if scope is not None else PlantScope()
    token = _current_scope.set(scope)
    try:
        yield scope
    finally:
        _current_scope.reset(token)


def scope_for(channel: HWChannel) -> PlantScope:
    """The scope a backend built now for ``channel`` uses without an explicit one."""
    scope = _current_scope.get()
    if scope is not None:
        return scope
    file, node = (channel.loc.file, channel.loc.xpath.rpartition("/")[0]) if channel.loc else ("<memory>", "")
    with _scopes_lock:
        return _node_scopes.setdefault((file, node), PlantScope(name=f"{file}:{node}"))


class SimulationHook(abc.ABC):
    """A simulated world, advanced lazily to its clock's time whenever a channel touches it.

    A backend serving channels from a simulated world shares one hook between them and calls
    ``sync()`` with ``lock`` held before each read or write; ``sync`` calls ``advance(start, end)``
    to move the world over the time since the previous access (never backwards). The loopback plant
    integrates its equation there; a physics backend steps its engine by as many fixed steps as
    fit. With a :class:`ManualClock`, time moves only when a test or a lock-step driver says so.
    """

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.lock = threading.RLock()
        self.time: float | None = None  # None until the first access starts the world

    def sync(self) -> float:
        """Advance the world to the clock's time (call with ``lock`` held); returns that time."""
        now = self.clock()
        if self.time is None:
            self.start(now)
            self.time = now
        elif now > self.time:
            self.advance(self.time, now)
            self.time = now
        return self.time

    def start(self, now: float) -> None:
        """Set the world up at its first access, at time ``now``."""
        return None  # optional hook

    @abc.abstractmethod
    def advance(self, start: float, end: float) -> None:
        """Move the world from time ``start`` to ``end`` (seconds, ``end > start``)."""
