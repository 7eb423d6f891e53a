"""Records of behaviors, composition, missions, plans and validation (schemas/missions.xsd)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from ..binding import Record, attr, child, children, text
from ..expressions import TRANSITION, Vocabulary
from .conditions import ConditionRecord
from .params import Param


@dataclass(frozen=True, kw_only=True)
class Configure(Record):
    """<Configure>: a parameter value a behavior sets on a service."""

    TAG = "Configure"
    parameter: str = attr()
    value: str = attr()


@dataclass(frozen=True, kw_only=True)
class Require(Record):
    """<Require>: a quality requirement (QR) a behavior asks of a service."""

    TAG = "Require"
    measure: str = attr()
    lower: float | None = attr(default=None)
    upper: float | None = attr(default=None)
    probability: float = attr(default=0.9)


@dataclass(frozen=True, kw_only=True)
class Uses(Record):
    """<Uses>: a service a behavior uses (§5.1.1)."""

    TAG = "Uses"
    service: str = attr()
    as_: str | None = attr(xml="as", default=None)
    configure: tuple[Configure, ...] = children()
    requires: tuple[Require, ...] = children()

    @property
    def alias(self) -> str:
        """The name conditions use for this service."""
        return self.as_ or self.service.split(".", 1)[1]

    @property
    def resource(self) -> str:
        """The SmartResource part of ``service`` (``RESOURCE.SERVICE``)."""
        return self.service.split(".", 1)[0]

    @property
    def service_name(self) -> str:
        """The service part of ``service`` (``RESOURCE.SERVICE``)."""
        return self.service.split(".", 1)[1]


@dataclass(frozen=True, kw_only=True)
class BehaviorPort(Record):
    """A behavior input or output: a topic or a plan signal."""

    name: str = attr()
    topic: str | None = attr(default=None)
    signal: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class BehaviorInput(BehaviorPort):
    """<Input>: an input stimulus of a behavior."""

    TAG = "Input"


@dataclass(frozen=True, kw_only=True)
class BehaviorOutput(BehaviorPort):
    """<Output>: an output of a behavior."""

    TAG = "Output"


@dataclass(frozen=True, kw_only=True)
class Behavior(Record):
    """<Behavior>: an individual behavior built on services (§5.1)."""

    TAG = "Behavior"
    name: str = attr()
    kind: str = attr()
    progress: Literal["traceable", "untraceable"] = attr(default="traceable")
    timeout: float | None = attr(default=None)
    description: str | None = attr(default=None)
    params: tuple[Param, ...] = children()
    uses: tuple[Uses, ...] = children()
    inputs: tuple[BehaviorInput, ...] = children()
    outputs: tuple[BehaviorOutput, ...] = children()


@dataclass(frozen=True, kw_only=True)
class MatrixService(Record):
    """<Service> of a composition matrix: row and column index by order."""

    TAG = "Service"
    ref: str = attr()


@dataclass(frozen=True, kw_only=True)
class Row(Record):
    """<Row>: one row of a composition matrix, values from 0 to 1."""

    TAG = "Row"
    values: tuple[float, ...] = text()


@dataclass(frozen=True, kw_only=True)
class CompositionMatrix(Record):
    """<CompositionMatrix>: the Service Composition matrix SC of eq. 5.1."""

    TAG = "CompositionMatrix"
    name: str = attr()
    rule: Literal["strict", "normalize"] = attr(default="normalize")
    services: tuple[MatrixService, ...] = children()
    rows: tuple[Row, ...] = children()

    def refs(self) -> list[str]:
        """The ``RESOURCE.SERVICE`` references of the matrix's columns, in order (eq. 5.1)."""
        return [s.ref for s in self.services]


@dataclass(frozen=True, kw_only=True)
class State(Record):
    """<State>: a mission state running a behavior or a nested mission (§5.2)."""

    TAG = "State"
    name: str = attr()
    behavior: str | None = attr(default=None)
    mission: str | None = attr(default=None)
    timeout: float | None = attr(default=None)
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Final(Record):
    """<Final>: a final state; entering it ends the mission with this outcome."""

    TAG = "Final"
    name: str = attr()
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Transition(ConditionRecord):
    """<Transition>: a one-way transition taken when its condition holds (parsed once: ``condition``)."""

    TAG = "Transition"
    VOCABULARY: ClassVar[Vocabulary] = TRANSITION
    from_: str = attr(xml="from")
    to: str = attr()
    when: str = attr(default="done()")


@dataclass(frozen=True, kw_only=True)
class Mission(Record):
    """<Mission>: a hierarchical finite state machine of behaviors (§5.2)."""

    TAG = "Mission"
    name: str = attr()
    initial: str = attr()
    composition: str | None = attr(default=None)
    description: str | None = attr(default=None)
    states: tuple[State, ...] = children()
    finals: tuple[Final, ...] = children()
    transitions: tuple[Transition, ...] = children()

    def state(self, name: str) -> State | None:
        """The ``<State>`` named ``name``, None if the mission has none."""
        return next((s for s in self.states if s.name == name), None)

    def outcomes(self) -> list[str]:
        """Names of the mission's ``<Final>`` states, its outcomes (the first is success by convention)."""
        return [f.name for f in self.finals]


@dataclass(frozen=True, kw_only=True)
class Agent(Record):
    """<Agent>: a robot agent of a plan and the mission it runs."""

    TAG = "Agent"
    name: str = attr()
    node: str = attr()
    mission: str = attr()
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Signal(Record):
    """<Signal>: a cross-agent signal emitted by a state of an agent's mission."""

    TAG = "Signal"
    name: str = attr()
    agent: str = attr()
    state: str = attr()
    on: Literal["entry", "done", "exit"] = attr(default="done")
    topic: str | None = attr(default=None)
    type: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Dependency(Record):
    """<Dependency>: a state of one agent waits for another agent's signal."""

    TAG = "Dependency"
    agent: str = attr()
    state: str = attr()
    signal: str = attr()


@dataclass(frozen=True, kw_only=True)
class Expect(Record):
    """<Expect>: where an environment object or a simulated robot must end when the plan succeeds (D300, D306)."""

    TAG = "Expect"
    object: str = attr()
    on: str | None = attr(default=None)
    in_: str | None = attr(xml="in", default=None)
    within: float = attr(default=0.5)


@dataclass(frozen=True, kw_only=True)
class Plan(Record):
    """<Plan>: missions assigned to agents and the signals tying them (§5.3)."""

    TAG = "Plan"
    name: str = attr()
    lost_after: float = attr(default=5.0)
    description: str | None = attr(default=None)
    agents: tuple[Agent, ...] = children()
    signals: tuple[Signal, ...] = children()
    dependencies: tuple[Dependency, ...] = children()
    expects: tuple[Expect, ...] = children()

    def signal_topic(self, signal: Signal) -> str:
        """Topic of ``signal``: its ``topic`` attribute, else ``/plan/PLAN/SIGNAL`` (§5.3)."""
        return signal.topic or f"/plan/{self.name}/{signal.name}"


@dataclass(frozen=True, kw_only=True)
class Randomise(Record):
    """<Randomise>: what ``ckm-bench mission`` moves per seed (D301); ``objects`` None: every movable object."""

    TAG = "Randomise"
    objects: tuple[str, ...] | None = attr(default=None)
    object_xy: float = attr(xml="objectXY", default=0.03)
    object_yaw: float = attr(default=0.3)
    start_xy: float = attr(xml="startXY", default=0.15)
    start_yaw: float = attr(default=0.2)


@dataclass(frozen=True, kw_only=True)
class Validation(Record):
    """<Validation>: off-line validation settings (§5.4, eq. 5.7) and the bench's <Randomise>."""

    TAG = "Validation"
    p_min: float = attr(default=0.9)
    k_max: int = attr(default=100)
    coverage: float = attr(default=1.0)
    step: float = attr(default=0.1)
    horizon: float = attr(default=3600.0)
    randomise: Randomise | None = child(default=None)
