"""Plan-level validation (thesis §5.3–5.4; issue G point 4): the plan's wait-for graph.

Each mission is checked alone by :mod:`.static`; a plan can still hang when its agents wait for
one another. Each agent's top mission is flattened into one networkx DiGraph (nested missions
included: a nested state leads into its mission's initial state, and its mission's finals lead
on along the transitions that accept that outcome). A state *waits for* signal σ when a plan
``<Dependency>`` says so, when its behavior reads σ as an ``<Input signal=…>``, or for each of its
transitions whose condition cannot hold without ``signal('σ')``. An emission of σ (its
``<Signal agent state on>``) *needs* σ' when, with the edges that wait for σ' removed from its
sender's graph, the emitting state can no longer be reached (``on="entry"``) or left (``done``,
``exit``). The signals and their needs form the wait-for graph (docs/decisions.md D67):

- a cycle is a **deadlock** among as many agents as it names (``deadlock``, error, reported at
  every Dependency or transition of the cycle);
- a Dependency of agent A on σ, where σ needs (transitively) a signal A emits only after it has
  left the waiting state for good, can only arrive once A no longer waits (``late-signal``);
- a Dependency on σ emitted by a state on no path of its sender to its success final
  (``signal-off-success-path``), or that can never be emitted (``signal-never-emitted``);
- a Signal with a ``type`` whose emitting state's behavior writes no ``<Output signal=…>`` for it
  would fail at run time (``signal-without-payload``); a behavior that writes a signal's payload
  in a state that does not send that signal writes in vain (``payload-never-sent``, a warning).

:func:`assumable_signals` tells the fake interaction which ``signal()`` it may take as true.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.binding import Record
from ckmconf.expressions import Condition
from ckmconf.model import System
from ckmconf.model.missions import Behavior, Mission, Plan, Signal, Transition

from ..solver import solve
from .findings import Finding, finding, ordered


@dataclass
class AgentGraph:
    """One agent's flattened mission: nodes are state paths (``Nav/NAV``) and finals (``#done``)."""

    agent: str
    mission: Mission
    graph: nx.DiGraph = field(default_factory=nx.DiGraph)
    start: str = ""
    success: str | None = None
    waits: dict[tuple[str, str], list[tuple[str, str]]] = field(default_factory=dict)
    """(state node, signal) → the edges that wait for it (all out-edges for a blocking wait)."""
    why: dict[tuple[str, str], Record] = field(default_factory=dict)
    """(state node, signal) → the record stating the wait (Dependency, Behavior input or Transition)."""
    behaviors: dict[str, Behavior] = field(default_factory=dict)
    """State node → the behavior it runs."""

    def reachable(self, node: str, removed: Sequence[tuple[str, str]] = ()) -> bool:
        """True if ``node`` can be reached from the start with the ``removed`` edges taken out."""
        graph = self.graph
        if removed:
            graph = self.graph.copy()
            graph.remove_edges_from(removed)
        return node in graph and (node == self.start or nx.has_path(graph, self.start, node))

    def can_emit(self, signal: Signal, removed: Sequence[tuple[str, str]] = ()) -> bool:
        """True if ``signal``'s state is still entered (``entry``) or left (``done``/``exit``) without ``removed``."""
        node = signal.state
        if not self.reachable(node, removed):
            return False
        if signal.on == "entry":
            return True
        kept = set(self.graph.out_edges(node)) - set(removed)
        inner = [n for n in self.graph.nodes if n.startswith(f"{node}/#")]  # a nested mission's finals
        return bool(kept) or any(self.reachable(n, removed) for n in inner)


def _requires(condition: Condition, signal: str) -> bool:
    """Whether the condition cannot hold while ``signal('signal')`` is false."""
    return solve([condition], 0, {("call", "signal", signal): False}) is None


def _calls(transition: Transition) -> tuple[Condition | None, dict[str, list[str]]]:
    """The transition's condition as parsed at load (None if it does not parse: the static checks
    report it) and the string arguments of its calls by function (``outcome``, ``signal``), in order."""
    if transition.condition_error is not None:
        return None, {}
    calls: dict[str, list[str]] = {}
    for function, args in transition.condition.calls:
        calls.setdefault(function, []).extend(a for a in args if isinstance(a, str))
    return transition.condition, calls


def flatten(system: System, agent: str, mission: Mission) -> AgentGraph:
    """The agent's mission as one graph, nested missions inlined (see the module docstring)."""
    flat = AgentGraph(agent, mission)
    finals = _add(system, flat, mission, "", {mission.name})
    flat.start = mission.initial
    flat.success = finals.get(mission.finals[0].name) if mission.finals else None
    return flat


def _add(system: System, flat: AgentGraph, mission: Mission, prefix: str, seen: set[str]) -> dict[str, str]:
    graph = flat.graph
    final_nodes = {f.name: f"{prefix}#{f.name}" for f in mission.finals}
    graph.add_nodes_from(final_nodes.values())
    children: dict[str, dict[str, str]] = {}
    for state in mission.states:
        node = prefix + state.name
        graph.add_node(node)
        nested = system.mission(state.mission) if state.mission and state.mission not in seen else None
        if nested is not None:
            graph.add_edge(node, f"{node}/{nested.initial}")
            children[state.name] = _add(system, flat, nested, f"{node}/", seen | {nested.name})
        behavior = system.behavior(state.behavior) if state.behavior else None
        if behavior is not None:
            flat.behaviors[node] = behavior
        for port in behavior.inputs if behavior is not None else ():
            if port.signal is not None:
                flat.why.setdefault((node, port.signal), port)
    for transition in mission.transitions:
        source = prefix + transition.from_
        target = final_nodes.get(transition.to, prefix + transition.to)
        child = children.get(transition.from_)
        edges: list[tuple[str, str]] = []
        condition, calls = _calls(transition)
        if child is None:
            edges.append((source, target))
        else:
            named = calls.get("outcome", [])
            if named:
                edges += [(child[o], target) for o in named if o in child]
            elif "done" in calls:
                edges += [(final, target) for final in child.values()]
            else:  # an outer condition (a timeout) pre-empts the nested mission anywhere
                edges += [(source, target), *((final, target) for final in child.values())]
        graph.add_edges_from(edges)
        for signal in set(calls.get("signal", [])):
            if condition is not None and _requires(condition, signal):
                flat.waits.setdefault((source, signal), []).extend(edges)
                flat.why.setdefault((source, signal), transition)
    return final_nodes


def _blocking(flat: AgentGraph, node: str, signal: str, record: Record) -> None:
    """A wait that holds every way out of ``node`` (a Dependency, a behavior's signal input)."""
    inner = [n for n in flat.graph.nodes if n.startswith(f"{node}/")]
    edges = [e for n in (node, *inner) for e in flat.graph.out_edges(n)]
    flat.waits[(node, signal)] = list(dict.fromkeys([*flat.waits.get((node, signal), []), *edges]))
    flat.why[(node, signal)] = record


@dataclass
class PlanGraph:
    """A ``<Plan>``'s agents' graphs and its signals' needs (the wait-for graph, §5.3)."""

    plan: Plan
    agents: dict[str, AgentGraph]
    needs: nx.DiGraph
    """Signal σ → σ' when emitting σ needs σ'; each edge carries the waits (agent, node) behind it."""


def build(system: System, plan: Plan) -> PlanGraph:
    """Flatten every agent of ``plan`` and compute which signal emissions need which signals."""
    agents: dict[str, AgentGraph] = {}
    for agent in plan.agents:
        mission = system.mission(agent.mission)
        if mission is not None:
            agents[agent.name] = flatten(system, agent.name, mission)
    for dependency in plan.dependencies:
        flat = agents.get(dependency.agent)
        if flat is not None and dependency.state in flat.graph:
            _blocking(flat, dependency.state, dependency.signal, dependency)
    for flat in agents.values():
        for (node, name), record in list(flat.why.items()):
            if (node, name) not in flat.waits:  # a behavior's signal input: it waits whatever the transitions
                _blocking(flat, node, name, record)
    needs = nx.DiGraph()
    needs.add_nodes_from(s.name for s in plan.signals)
    for signal in plan.signals:
        flat = agents.get(signal.agent)
        if flat is None or not flat.can_emit(signal):
            continue
        for (node, waited), edges in flat.waits.items():
            if not flat.can_emit(signal, edges):
                waits = needs.edges[signal.name, waited]["waits"] if needs.has_edge(signal.name, waited) else []
                needs.add_edge(signal.name, waited, waits=[*waits, (flat.agent, node)])
    return PlanGraph(plan, agents, needs)


def check_plan(system: System, plan: Plan) -> list[Finding]:
    """Every plan-level finding of ``plan`` (see the module docstring)."""
    built = build(system, plan)
    found: list[Finding] = []
    signals = {s.name: s for s in plan.signals}
    in_cycle: set[str] = set()
    for cycle in nx.simple_cycles(built.needs):
        in_cycle.update(cycle)
        steps = []
        records: list[Record] = []
        for index, name in enumerate(cycle):
            needed = cycle[(index + 1) % len(cycle)]
            for agent, node in built.needs.edges[name, needed]["waits"]:
                steps.append(f"{agent} waits at {node} for {needed!r} before it can send {name!r}")
                records.append(built.agents[agent].why[(node, needed)])
        involved = sorted({signals[n].agent for n in cycle if n in signals})
        message = f"deadlock among {len(involved)} agent(s) ({', '.join(involved)}): " + "; ".join(steps)
        for record in dict.fromkeys(records):
            found.append(finding("deadlock", "error", message, record, mission=plan.name))
    closure = nx.transitive_closure(built.needs, reflexive=False)
    for dependency in plan.dependencies:
        signal = signals.get(dependency.signal)
        sender = built.agents.get(signal.agent) if signal is not None else None
        receiver = built.agents.get(dependency.agent)
        if signal is None or sender is None or receiver is None:
            continue  # the reference checks report these
        where = f"{signal.agent}'s {signal.state} ({signal.on})"
        if not sender.can_emit(signal):
            message = f"{dependency.agent} waits at {dependency.state} for {signal.name!r}, which {where} never sends"
            found.append(finding("signal-never-emitted", "error", message, dependency, mission=plan.name))
            continue
        if not _on_success_path(sender, signal):
            message = (
                f"{dependency.agent} waits at {dependency.state} for {signal.name!r}, but {where} lies on no "
                f"path of {signal.agent} to its success final: on its way to success it never sends it"
            )
            found.append(finding("signal-off-success-path", "error", message, dependency, mission=plan.name))
        if signal.name in in_cycle:
            continue
        for needed in closure.successors(signal.name) if signal.name in closure else ():
            other = signals.get(needed)
            if other is None or other.agent != dependency.agent or dependency.state not in receiver.graph:
                continue
            if other.state in receiver.graph and not nx.has_path(receiver.graph, other.state, dependency.state):
                message = (
                    f"{dependency.agent} waits at {dependency.state} for {signal.name!r}, which can only be sent "
                    f"after {dependency.agent} has sent {needed!r} at {other.state}, after which it never waits at "
                    f"{dependency.state} again: the signal arrives too late"
                )
                found.append(finding("late-signal", "error", message, dependency, mission=plan.name))
                break
    for signal in plan.signals:
        found += _payload_findings(system, plan, signal)
    found += _unsent_payloads(plan, built)
    return ordered(found)


def _unsent_payloads(plan: Plan, built: PlanGraph) -> list[Finding]:
    """Behavior outputs that supply a signal's payload in a state that does not send that signal."""
    found = []
    senders = {(s.name, s.agent, s.state) for s in plan.signals}
    names = {s.name for s in plan.signals}
    for flat in built.agents.values():
        for node, behavior in flat.behaviors.items():
            for port in behavior.outputs:
                if port.signal in names and (port.signal, flat.agent, node) not in senders:
                    message = (
                        f"behavior {behavior.name!r} writes the payload of {port.signal!r} in {flat.agent}'s {node}, "
                        f"which does not send it (plan {plan.name!r}): that payload is never sent"
                    )
                    found.append(finding("payload-never-sent", "warning", message, port, mission=plan.name))
    return found


def _on_success_path(flat: AgentGraph, signal: Signal) -> bool:
    if flat.success is None:
        return False
    node = signal.state
    if not flat.reachable(node):
        return False
    return node == flat.success or nx.has_path(flat.graph, node, flat.success)


def _payload_findings(system: System, plan: Plan, signal: Signal) -> list[Finding]:
    if signal.type is None:
        return []
    agent = next((a for a in plan.agents if a.name == signal.agent), None)
    mission = system.mission(agent.mission) if agent is not None else None
    parts = signal.state.split("/")
    while mission is not None and len(parts) > 1:
        state = mission.state(parts.pop(0))
        mission = system.mission(state.mission) if state is not None and state.mission else None
    state = mission.state(parts[0]) if mission is not None else None
    if state is not None and state.mission is not None:
        message = (
            f"signal {signal.name!r} carries a {signal.type}, but {signal.agent}'s {signal.state} runs the "
            f"mission {state.mission!r}, not a behavior that could write it: emit it from a behavior state"
        )
        return [finding("signal-without-payload", "error", message, signal, mission=plan.name)]
    if state is None or state.behavior is None:
        return []
    behavior = system.behavior(state.behavior)
    if behavior is None or any(o.signal == signal.name for o in behavior.outputs):
        return []
    message = (
        f"signal {signal.name!r} carries a {signal.type}, but behavior {behavior.name!r} of {signal.agent}'s "
        f"{signal.state} writes no <Output signal={signal.name!r}>: it would fail when sent"
    )
    return [finding("signal-without-payload", "error", message, signal, mission=plan.name)]


def check_plans(system: System) -> list[Finding]:
    """:func:`check_plan` over every plan of the system."""
    return ordered([f for plan in system.plans for f in check_plan(system, plan)])


def assumable_signals(system: System, mission: str) -> set[str] | None:
    """Signals the fake interaction may take as received while running ``mission``.

    None when the system declares no plan (nothing to judge a signal by: every signal is an
    outside input). Otherwise the signals of the plans that some agent can send and that are in
    no deadlock — from agents other than the one running ``mission``.
    """
    if not system.plans:
        return None
    allowed: set[str] = set()
    for plan in system.plans:
        built = build(system, plan)
        cyclic = {n for cycle in nx.simple_cycles(built.needs) for n in cycle}
        for signal in plan.signals:
            sender = built.agents.get(signal.agent)
            if sender is not None and signal.name not in cyclic and sender.can_emit(signal):
                allowed.add(signal.name)
    return allowed
