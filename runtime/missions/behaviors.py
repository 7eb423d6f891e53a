"""Behaviors (thesis §5.1): the states of a mission, written against Smart Resource services.

A behavior is built from its ``<Behavior>`` record through the registry (category ``behavior``,
by ``kind``) with no I/O; the mission starts it when its state is entered, steps it every
mission period, and stops it on exit. It reaches the world only through its
:class:`BehaviorContext`: the services it ``<Uses>`` (by alias: configure them, read their
outputs and quality measures), its ``<Input>`` values (topics or plan signals) and its
``<Output>`` publishers — never a robot. Each step returns a :class:`BehaviorStatus`: progress in
[0, 1], done, failed. "Non-traceable" behaviors (§5.1.2: waiting for a recognition, for the
other robot) report no meaningful progress and rely on their timeout.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol

from ckmconf.model import System
from ckmconf.model.environment import Environment
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import Require

from ..kernel.interfaces import read_params
from ..resources.api import Bounds


@dataclass(frozen=True)
class BehaviorStatus:
    """What one step of a behavior reports (its progress, for mission progress and eq. 5.1)."""

    progress: float = 0.0
    done: bool = False
    failed: bool = False
    detail: str = ""


class ServiceHandle(Protocol):
    """A service a behavior ``<Uses>`` (§5.1.1): a network client in a live run, a simulation off-line."""

    ref: str

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        """Send the behavior's Configure/Require (never blocks the mission)."""

    def output(self, name: str) -> Any:
        """The newest value of an output (None before the first)."""

    def measures(self) -> dict[str, float]:
        """The newest value of each quality measure."""

    def samples(self, measure: str) -> list[float]:
        """The recent values of a measure (for the service state of eq. 5.1)."""

    def running(self) -> bool:
        """Heard from recently."""


@dataclass
class BehaviorContext:
    """Everything a behavior may touch."""

    services: Mapping[str, ServiceHandle]
    """By alias (``as=``, or the service name)."""
    inputs: Mapping[str, Callable[[], Any]]
    """By input name: the newest value of its topic or plan signal (None before the first)."""
    outputs: Mapping[str, Callable[[Any], None]]
    """By output name: publish a value on its topic."""
    now: Callable[[], float]
    """Seconds since the state was entered (simulated time off-line)."""
    events: list[dict[str, Any]] = field(default_factory=list)
    demand: Callable[[bool], None] = lambda wanted: None
    """Told True when the state is entered and False when it is left: the agent then asks for the
    topics the behavior reads, so lazy sensors and services work for it only meanwhile (D245)."""
    heard: Mapping[str, Callable[[], int]] = field(default_factory=dict)
    """By input name: how many values it has received so far (a count that only grows), so a behavior
    can tell a value heard after its state was entered from one left from before (D268)."""
    environment: Environment | None = None
    """The system's ``<Environment>`` (§6.1): its Areas and Objects, for behaviors that plan on the map."""

    def log(self, message: str, **detail: Any) -> None:
        """Keep a note for the mission log (written as a ``log`` record of the state, §7.5)."""
        self.events.append({"message": message, **detail})


def requirements_of(requires: tuple[Require, ...]) -> tuple[Bounds, ...]:
    """The ``<Require>`` elements of a ``<Uses>`` as the quality bounds a service is asked for (§4.2.1.2)."""
    return tuple(Bounds(r.measure, r.lower, r.upper, r.probability) for r in requires)


class Behavior(abc.ABC):
    """The behavior interface (§5.1, ``<Behavior kind>``). ``PARAMS`` maps accepted Params to defaults."""

    PARAMS: ClassVar[Mapping[str, Any]] = {}

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """What is wrong with ``record`` beyond its single Params (a Param naming no input, no Area of
        the map, two Params that exclude each other), as (the element to place it at, the message):
        ``verify`` reports each at its ``FILE:LINE:COL`` before anything starts (D268). None by default."""
        return []

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        self.record = record
        self.name = record.name
        self.context = context
        self.params: dict[str, Any] = read_params(record.params, self.PARAMS, owner=self.owner)

    @property
    def owner(self) -> str:
        """How errors name this behavior: its ``<Behavior name>`` and ``kind``."""
        return f"behavior {self.record.name!r} ({self.record.kind})"

    def start(self) -> None:
        """Entered: configure the services as the record says (override to add, call super)."""
        for uses in self.record.uses:
            handle = self.context.services.get(uses.alias)
            if handle is not None:
                parameters = {c.parameter: c.value for c in uses.configure}
                handle.configure(parameters, requirements_of(uses.requires))

    @abc.abstractmethod
    def step(self) -> BehaviorStatus:
        """One mission period."""

    def stop(self) -> None:
        """Left (done, failed, timed out or pre-empted)."""
        return None  # optional hook

    # helpers for implementations
    def service(self, alias: str) -> ServiceHandle:
        """The handle of the service used as ``alias`` (``<Uses as=…>``); KeyError naming the behavior if none."""
        try:
            return self.context.services[alias]
        except KeyError:
            raise KeyError(f"{self.owner} uses no service {alias!r}") from None

    def read(self, name: str) -> Any:
        """Newest value of ``<Input name>`` (a topic or a plan signal's payload), None before the first."""
        source = self.context.inputs.get(name)
        return None if source is None else source()

    def heard(self, name: str) -> int | None:
        """How many values ``<Input name>`` has received so far; None when the host cannot tell."""
        count = self.context.heard.get(name)
        return None if count is None else count()

    def write(self, name: str, value: Any) -> None:
        """Publish ``value`` on ``<Output name>``; KeyError naming the behavior if it declares no such output."""
        sink = self.context.outputs.get(name)
        if sink is None:
            raise KeyError(f"{self.owner} has no output {name!r}")
        sink(value)
