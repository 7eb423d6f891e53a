"""SRFlowGen: the variable flow of a mission through the Smart Resources (thesis §5.4, Algorithm 2).

How we read the text (eq. 5.2–5.7, Algorithm 2, Fig. 5.7):

- **The system (eq. 5.2–5.4).** Processes are the services of the SmartResources (``sr_i`` with
  results ``R_i`` and quality measures ``Q_i``), the nodes' controllers, and the sources: node
  sensors, behavior outputs and plan signals. They form a networkx DiGraph, process → topic →
  process, from each ``Output``/``Sensor`` topic to each ``Input`` reading it; an internal topic
  is resolved on its own node (D10): :mod:`runtime.missions.validation.process_graph`.
- **The variables** ``v_i`` of a behavior ``f_pi`` (Algorithm 2, lines 2–4) are what it reads:
  each ``Input`` topic, each quality requirement ``Require`` of its ``Uses`` (eq. 5.5, the
  ``QR``), each ``alias.field`` the state's transitions test, and, for a ``Uses`` with no
  requirement, the used service's result.
- **EvalFlow** (lines 11–21) walks from a variable to the process producing it and on through
  that process's inputs until atomic processes (sources) are reached; every walk is a chain
  ``R_1:k``. ``k`` counts the processing steps (services and controllers) on the longest chain;
  a feedback loop (AMCL ↔ Displacement) counts each of its steps once.
- **The quality** (lines 5 and 15–16, "police qualities", eq. 5.6). Each service on the chains
  contributes the probability that it delivers within its *data-flow* policies — those on
  temporal and performance measures (deadline, latency, rate, reliability); spatial policies (CPU,
  memory) bound what the resource consumes, not what flows down the chain, so they are left out.
  A scenario's probability is the product of its data-flow policies' ``probability`` (eq. 4.4:
  the TCM keeps a scenario only while they hold; taken as independent), and the service's is its
  best scenario's (the TCM selects the best usable one, eq. 4.9); for the service a behavior
  ``Require``s something of, only the scenarios compatible with its requirements count (D37).
  ``P(QR(Q_k) | R_1:k)`` is a probability *conditional* on the resources of the chain: each step
  is judged given that the steps before it deliver, so eq. 5.7 must hold at every step and the
  variable's P is the weakest step's (not a product along the chain, which would be the joint
  probability the equation does not ask for). A service with no data-flow policy is *not
  characterised*: factor 1.0 (the model knows nothing against it), listed in the report, a
  warning only with ``strict`` (every use-case service outside §7.2 is in that case).
- **Eq. 5.7.** A variable passes when ``P > P_min`` and ``k < K_max`` (``<Validation>``), as
  written (strict ``>`` and ``<``). A chain that reaches a topic no process of the system produces
  is reported (``no-producer``, a warning: an operator or another system may publish it).

One ``quality-flow`` / ``chain-too-long`` finding per state, at its weakest variable's record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.binding import Record
from ckmconf.model import Behavior, Mission, Service, State, System, Validation
from ckmconf.model.missions import Require
from ckmconf.model.resources import Scenario

from .findings import Finding, finding, ordered
from .process_graph import ProcessGraph, node_label
from .requirements import compatible


@dataclass(frozen=True)
class VariableFlow:
    """One variable v_i of a behavior state traced back to its sources (EvalFlow, Algorithm 2)."""

    name: str
    chains: tuple[tuple[str, ...], ...]
    k: int
    probability: float
    factors: tuple[tuple[str, float], ...] = ()
    uncharacterised: tuple[str, ...] = ()
    truncated: bool = False
    record: Record | None = field(default=None, compare=False, repr=False)

    def to_json(self) -> dict[str, object]:
        """The variable's k, P, chains and per-service factors as JSON (``--json`` output)."""
        return {
            "variable": self.name,
            "k": self.k,
            "probability": self.probability,
            "chains": [list(c) for c in self.chains],
            "factors": dict(self.factors),
            "uncharacterised": list(self.uncharacterised),
            "truncated": self.truncated,
        }


@dataclass(frozen=True)
class StateFlow:
    """The variables of one behavior state; its P is the weakest variable's, its k the longest."""

    mission: str
    state: str
    behavior: str
    variables: tuple[VariableFlow, ...]

    @property
    def probability(self) -> float:
        """The state's P: its weakest variable's (1.0 with no variables), compared to P_min (eq. 5.7)."""
        return min((v.probability for v in self.variables), default=1.0)

    @property
    def k(self) -> int:
        """The state's k: its longest variable chain, compared to K_max (eq. 5.7)."""
        return max((v.k for v in self.variables), default=0)

    def to_json(self) -> dict[str, object]:
        """The state's k, P and variables as JSON."""
        return {
            "mission": self.mission,
            "state": self.state,
            "behavior": self.behavior,
            "k": self.k,
            "probability": self.probability,
            "variables": [v.to_json() for v in self.variables],
        }


@dataclass(frozen=True)
class FlowReport:
    """SRFlowGen (Algorithm 2) over a mission and the missions it nests, against ``<Validation>`` (eq. 5.7)."""

    mission: str
    p_min: float
    k_max: int
    states: tuple[StateFlow, ...]

    def state(self, mission: str, state: str) -> StateFlow | None:
        """The flow of ``state`` in ``mission``, None if it runs no behavior."""
        return next((s for s in self.states if s.mission == mission and s.state == state), None)

    def to_json(self) -> dict[str, object]:
        """The report with its ``<Validation>`` thresholds pMin/kMax, as JSON."""
        return {
            "mission": self.mission,
            "pMin": self.p_min,
            "kMax": self.k_max,
            "states": [s.to_json() for s in self.states],
        }


def srflowgen(
    system: System, mission_name: str, validation: Validation | None = None, *, strict: bool = False
) -> tuple[list[Finding], FlowReport]:
    """Trace every behavior state of the mission (nested ones included) and check eq. 5.7."""
    settings = validation or system.validation or Validation()
    flows = _Flows(system, settings, strict)
    mission = system.mission(mission_name)
    if mission is None:
        known = ", ".join(m.name for m in system.missions) or "none"
        message = f"mission {mission_name!r} does not exist in system {system.name!r} (missions: {known})"
        flows.findings.append(finding("unknown-mission", "error", message, system, mission=mission_name))
    else:
        flows.visit(mission, set())
    return ordered(flows.findings), FlowReport(mission_name, settings.p_min, settings.k_max, tuple(flows.states))


class _Flows:
    def __init__(self, system: System, settings: Validation, strict: bool) -> None:
        self.system = system
        self.settings = settings
        self.strict = strict
        self.graph = ProcessGraph(system)
        self.states: list[StateFlow] = []
        self.findings: list[Finding] = []
        self.reported: set[str] = set()  # topics and services already reported

    def visit(self, mission: Mission, seen: set[str]) -> None:
        seen = seen | {mission.name}
        for state in mission.states:
            behavior = self.system.behavior(state.behavior) if state.behavior else None
            if behavior is not None:
                self._state(mission, state, behavior)
            nested = self.system.mission(state.mission) if state.mission else None
            if nested is not None and nested.name not in seen:  # recursion is a static-check error
                self.visit(nested, seen)

    def _state(self, mission: Mission, state: State, behavior: Behavior) -> None:
        variables = [self._trace(mission, state, *v) for v in self._variables(mission, state, behavior)]
        flow = StateFlow(mission.name, state.name, behavior.name, tuple(variables))
        self.states.append(flow)
        where = f"state {state.name!r} (behavior {behavior.name!r}) of mission {mission.name!r}"
        low = sorted((v for v in variables if v.probability <= self.settings.p_min), key=lambda v: v.probability)
        if low:
            self.findings.append(self._quality(mission.name, state.name, where, low))
        long = sorted((v for v in variables if v.k >= self.settings.k_max), key=lambda v: -v.k)
        if long:
            message = (
                f"{where}: {long[0].name} is produced through a chain of k = {long[0].k} steps, not < K_max ="
                f" {self.settings.k_max} (eq. 5.7): {' <- '.join(long[0].chains[0]) if long[0].chains else ''};"
                " shorten the chain or raise kMax"
            )
            self.findings.append(
                finding("chain-too-long", "error", message, long[0].record, mission=mission.name, state=state.name)
            )

    def _quality(self, mission: str, state: str, where: str, low: list[VariableFlow]) -> Finding:
        worst = low[0]
        weakest = min(worst.factors, key=lambda f: f[1], default=None)
        detail = f"; weakest service {weakest[0]} ({weakest[1]:.3g})" if weakest else ""
        others = f"; also below: {', '.join(v.name for v in low[1:])}" if len(low) > 1 else ""
        message = (
            f"{where}: P(QR | R_1:k) = {worst.probability:.3g} for {worst.name}, not > P_min ="
            f" {self.settings.p_min:g} (eq. 5.7){detail}{others}; raise the probability of the services'"
            " policies, depend on fewer services, or lower pMin"
        )
        return finding("quality-flow", "error", message, worst.record, mission=mission, state=state)

    def _variables(
        self, mission: Mission, state: State, behavior: Behavior
    ) -> list[tuple[str, str, Record, tuple[Require, ...]]]:
        """(name, graph node of its producer, record to point at, requirements on that service)."""
        found: dict[str, tuple[str, str, Record, tuple[Require, ...]]] = {}
        aliases = {}
        for uses in behavior.uses:
            provided = self.system.service(uses.service)
            if provided is None:
                continue  # static check: service-not-provided
            node = f"service:{uses.service}"
            aliases[uses.alias] = (node, uses.requires, provided[1])
            for require in uses.requires:
                found.setdefault(
                    f"{uses.alias}.{require.measure}", (f"{uses.alias}.{require.measure}", node, require, uses.requires)
                )
            if not uses.requires:
                name = f"{uses.alias}.{provided[1].performance or 'result'}"
                found.setdefault(name, (name, node, uses, ()))
        for transition in mission.transitions:
            if transition.from_ != state.name or transition.condition_error is not None:
                continue
            for alias, field_name in transition.condition.attributes:
                if alias in aliases:
                    node, requires, _ = aliases[alias]
                    name = f"{alias}.{field_name}"
                    found.setdefault(name, (name, node, transition, requires))
        for port in behavior.inputs:
            if port.topic is not None:
                name = f"input {port.name} ({port.topic})"
                found.setdefault(name, (name, self.graph.topic(None, port.topic), port, ()))
        return list(found.values())

    def _trace(
        self, mission: Mission, state: State, name: str, head: str, record: Record, requires: tuple[Require, ...]
    ) -> VariableFlow:
        graph = self.graph.graph
        if head not in graph:
            graph.add_node(head)  # a topic nobody declares or produces
        upstream = nx.ancestors(graph, head) | {head}
        factors: list[tuple[str, float]] = []
        uncharacterised: list[str] = []
        for node in sorted(upstream):
            if not node.startswith("service:"):
                continue
            ref = node.removeprefix("service:")
            service = self.graph.services[ref]
            # Upstream services feed their own instance (D38), which this behavior's QR does not configure.
            probability = service_probability(service, requires if node == head else ())
            if probability is None:
                uncharacterised.append(ref)
                self._uncharacterised(mission, state, ref, service)
            else:
                factors.append((ref, probability))
        for node in sorted(upstream):
            if node.startswith("topic:") and graph.in_degree(node) == 0:
                self._no_producer(mission, state, node, record)
        chains, truncated = self.graph.chains(head, self.settings.k_max)
        return VariableFlow(
            name,
            chains,
            self.graph.longest(upstream, head),
            min((p for _, p in factors), default=1.0),
            tuple(factors),
            tuple(uncharacterised),
            truncated,
            record,
        )

    def _no_producer(self, mission: Mission, state: State, topic_node: str, record: Record) -> None:
        topic = topic_node.removeprefix("topic:")
        if topic in self.reported:
            return
        self.reported.add(topic)
        consumers = [c for c in self.graph.graph.successors(topic_node) if (c, topic_node) in self.graph.ports]
        port = self.graph.ports[(consumers[0], topic_node)] if consumers else record
        reader = f"read by {node_label(consumers[0])}" if consumers else f"an input of behavior {state.behavior!r}"
        message = (
            f"topic {topic!r}, {reader} on the flow of state {state.name!r} of mission {mission.name!r}, has no"
            " producer in the system (sensor, controller, service, behavior output or plan signal): unless"
            " something outside the system publishes it, what depends on it is never computed"
        )
        self.findings.append(finding("no-producer", "warning", message, port, mission=mission.name, state=state.name))

    def _uncharacterised(self, mission: Mission, state: State, ref: str, service: Service) -> None:
        if not self.strict or ref in self.reported:
            return
        self.reported.add(ref)
        message = (
            f"service {ref}, on the flow of state {state.name!r} of mission {mission.name!r}, has no quality"
            " policy: SRFlowGen counts it as certain (1.0); add a Scenario with Policies to characterise it"
        )
        self.findings.append(
            finding("quality-not-characterised", "warning", message, service, mission=mission.name, state=state.name)
        )


def service_probability(service: Service, requires: tuple[Require, ...] = ()) -> float | None:
    """Probability the service delivers within its data-flow policies (best compatible scenario);
    None when it has none (not characterised)."""
    spatial = {m.name for m in service.measures if m.domain == "spatial"}

    def flow(scenario: Scenario) -> list[float]:
        return [p.probability for p in scenario.policies if p.measure not in spatial]

    if not any(flow(s) for s in service.scenarios):
        return None
    usable = [s for s in service.scenarios if compatible(s, requires)]
    return max((math.prod(flow(s)) for s in usable), default=0.0)
