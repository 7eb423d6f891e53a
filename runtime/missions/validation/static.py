"""Static checks of a mission HFSM (thesis §5.4 and §7.5.1: "continuity and terminality").

Each mission becomes a networkx DiGraph: its states and finals are nodes, and each transition
that can fire is an edge. The rules (docs/decisions.md):

- **Priority.** A state's transitions are tried in document order and the first that holds fires
  (D14), so overlapping conditions are never ambiguous. What is wrong is a transition that can
  never fire because an earlier one always fires first: its condition implies the earlier one's
  (``done()`` before ``done() and x``, the same condition twice, ``a or b`` before ``a``). That is
  a ``shadowed-transition`` error; a disjunct shadowed alone is a ``redundant-condition`` warning.
  Conditions are compared in normal form (:mod:`.conditions`), syntactically: what is reported is
  proven, but not every shadowed transition is found.
- **Dead conditions** (``x and not x``, ``done() and failed()``, ``outcome('x')`` of a final the
  nested mission never reaches, ``timeout()`` with no timeout) do not make edges, so what only
  they lead to is unreachable. A transition with no other way to fire is an error
  (``never-true``, ``unreachable-outcome``); a dead part of a condition, a warning. A condition
  that does not parse is reported and otherwise assumed able to fire (no cascade).
- **Graph** (:mod:`.termination`). A state not reachable from the initial one is an error, a final
  one a warning; a reachable state with no transition that can fire is a ``dead-end``; one from
  which no final is reachable (a loop with no exit, or a path into a dead end) is ``non-terminating``.
- **Endings.** A behavior ends done or failed (never both), a nested mission in one of its
  reachable finals (and then ``done()`` holds for the parent, as the runtime does). For each way
  a state can end, some transition should be *sure* to fire afterwards — made only of literals
  that the ending makes true, ``timeout()`` when a timeout is set, or ``elapsed > c``. Otherwise
  the state may hang: ``unhandled-done`` / ``unhandled-failure`` / ``unhandled-outcome`` warnings.
- **References** are re-checked here because records may be built in memory: missing
  states/finals, behaviors, missions, signals, aliases and fields; nesting that recurses. What a
  behavior asks of the services is checked once per behavior (:mod:`.requirements`).
"""

from __future__ import annotations

from typing import Any

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.model import Final, Mission, State, System, Transition

from .conditions import Atom, Conjunction, contradictory, describe, dnf, implies
from .findings import Finding, arrow, finding, ordered
from .requirements import check_behavior, check_fields
from .termination import check_graph


def check_mission(system: System, mission_name: str, *, strict: bool = False) -> list[Finding]:
    """Static checks of one mission and, recursively, of the missions it nests.

    ``strict`` adds warnings for quality requirements the model cannot prove (no policy on them).
    """
    mission = system.mission(mission_name)
    if mission is None:
        known = ", ".join(m.name for m in system.missions) or "none"
        message = f"mission {mission_name!r} does not exist in system {system.name!r} (missions: {known})"
        return [finding("unknown-mission", "error", message, system, mission=mission_name)]
    checker = _Checker(system, strict)
    checker.analyse(mission)
    return ordered(checker.findings)


def nesting_graph(system: System) -> nx.DiGraph:
    """Missions, with an edge from each mission to every mission a state of it runs."""
    graph = nx.DiGraph()
    for mission in system.missions:
        graph.add_node(mission.name)
        for state in mission.states:
            if state.mission is not None:
                graph.add_edge(mission.name, state.mission)
    return graph


class _Checker:
    def __init__(self, system: System, strict: bool) -> None:
        self.system = system
        self.strict = strict
        self.findings: list[Finding] = []
        self.nesting = nesting_graph(system)
        self.reached: dict[str, set[str]] = {}  # mission → finals reachable from its initial state
        self.active: set[str] = set()
        self.behaviors: set[str] = set()
        self.signals = {s.name for plan in system.plans for s in plan.signals}
        self.agents = {a.name for plan in system.plans for a in plan.agents}

    def add(self, *found: Finding) -> None:
        self.findings.extend(found)

    def outcomes(self, name: str) -> set[str]:
        """Reachable finals of a nested mission (all of them while it is being analysed: recursion)."""
        mission = self.system.mission(name)
        if mission is None:
            return set()
        if name not in self.reached and name not in self.active:
            self.analyse(mission)
        return self.reached.get(name, set(mission.outcomes()))

    def analyse(self, mission: Mission) -> None:
        self.active.add(mission.name)
        states = {s.name: s for s in mission.states}
        finals = {f.name: f for f in mission.finals}
        for state in mission.states:
            self._check_state(mission, state)
        graph = nx.DiGraph()
        graph.add_nodes_from([*states, *finals])
        by_source: dict[str, list[tuple[Transition, list[Conjunction]]]] = {}
        opaque: set[str] = set()  # states with a condition we could not analyse
        for transition in mission.transitions:
            if self._check_ends(mission, transition, states, finals):
                continue
            state = states[transition.from_]
            earlier = by_source.setdefault(state.name, [])
            live = self._live(mission, state, transition, earlier)
            earlier.append((transition, live or []))
            if live is None:
                opaque.add(state.name)
            if (live is None or live) and transition.to in graph:
                graph.add_edge(transition.from_, transition.to)
        check_graph(self, mission, graph, states, finals, by_source, opaque)
        self.active.discard(mission.name)

    # ------------------------------------------------------------------ states and references

    def _check_state(self, mission: Mission, state: State) -> None:
        name = mission.name
        if (state.behavior is None) == (state.mission is None):
            message = f"state {state.name!r} must run exactly one of a behavior or a mission"
            self.add(finding("invalid-state", "error", message, state, mission=name, state=state.name))
        elif state.behavior is not None:
            behavior = self.system.behavior(state.behavior)
            if behavior is None:
                known = ", ".join(b.name for b in self.system.behaviors) or "none"
                message = f"state {state.name!r} runs behavior {state.behavior!r}, which is not defined ({known})"
                self.add(finding("missing-behavior", "error", message, state, mission=name, state=state.name))
            elif behavior.name not in self.behaviors:
                self.behaviors.add(behavior.name)
                self.add(*check_behavior(self.system, behavior, mission=name, state=state.name, strict=self.strict))
        elif state.mission is not None:
            if self.system.mission(state.mission) is None:
                known = ", ".join(m.name for m in self.system.missions)
                message = f"state {state.name!r} runs mission {state.mission!r}, which is not defined ({known})"
                self.add(finding("missing-mission", "error", message, state, mission=name, state=state.name))
            elif nx.has_path(self.nesting, state.mission, name):
                cycle = nx.shortest_path(self.nesting, state.mission, name)
                message = (
                    f"state {state.name!r} runs mission {state.mission!r}, which contains {name!r} again"
                    f" ({' -> '.join([name, *cycle])}): a mission cannot nest itself"
                )
                self.add(finding("recursive-mission", "error", message, state, mission=name, state=state.name))
            self.outcomes(state.mission)  # checks the nested mission (once; recursion is guarded)

    def _check_ends(
        self, mission: Mission, transition: Transition, states: dict[str, State], finals: dict[str, Final]
    ) -> bool:
        """Report missing ends; True when the transition leaves no existing state (nothing else to check)."""
        label = arrow(transition.from_, transition.to)
        where = {"mission": mission.name, "state": transition.from_, "transition": label}
        if transition.to not in states and transition.to not in finals:
            known = ", ".join([*states, *finals])
            message = (
                f"transition {label} goes to {transition.to!r}, which is no state or final of {mission.name!r}"
                f" ({known}); fix the name or add that state"
            )
            self.add(finding("missing-target", "error", message, transition, **where))
        if transition.from_ in finals:
            message = f"transition {label} leaves final state {transition.from_!r}; a final state ends the mission"
            self.add(finding("transition-from-final", "error", message, transition, **where))
            return True
        if transition.from_ not in states:
            message = f"transition {label} leaves {transition.from_!r}, which is no state of {mission.name!r}"
            self.add(finding("missing-source", "error", message, transition, **where))
            return True
        return False

    # ------------------------------------------------------------------ conditions

    def _live(
        self,
        mission: Mission,
        state: State,
        transition: Transition,
        earlier: list[tuple[Transition, list[Conjunction]]],
    ) -> list[Conjunction] | None:
        """The conjunctions of the transition's condition that can make it fire; None: not analysable."""
        label = arrow(transition.from_, transition.to)
        where = {"mission": mission.name, "state": state.name, "transition": label}
        error = transition.condition_error  # parsed once, when the record was read
        if error is not None:
            self.add(finding("invalid-condition", "error", f"transition {label}: {error}", transition, **where))
            return None  # reported; assume nothing about it rather than cascade
        condition = transition.condition
        behavior = self.system.behavior(state.behavior) if state.behavior else None
        if behavior is not None or state.mission is not None:  # a missing behavior is reported on the state
            self.add(*check_fields(self.system, behavior, condition.attributes, transition, mission=mission.name))
        dead, unreached = self._dead_calls(mission.name, state, transition, condition.calls)
        conjunctions = dnf(condition)
        if conjunctions is None:
            return None  # too large to analyse: it may fire, and proves nothing about the others
        live: list[Conjunction] = []
        impossible: list[Conjunction] = []
        for conjunction in conjunctions:
            if any(lit.positive and lit.atom in dead for lit in conjunction):
                continue
            if contradictory(conjunction, behavior=state.behavior is not None):
                impossible.append(conjunction)
            else:
                live.append(conjunction)
        for outcome, nested in unreached:
            message = (
                f"transition {label} waits for outcome {outcome!r}, but mission {nested!r} can never end there"
                " (that final is unreachable)"
            )
            self.add(finding("unreachable-outcome", "warning" if live else "error", message, transition, **where))
        for conjunction in impossible:
            message = f"transition {label}: {describe(conjunction)!r} can never hold; remove or fix it"
            if live:
                self.add(finding("redundant-condition", "warning", message, transition, **where))
            else:
                self.add(finding("never-true", "error", message, transition, **where))
        return self._unshadowed(transition, live, earlier, where)

    def _dead_calls(
        self, mission: str, state: State, transition: Transition, calls: list[tuple[str, tuple[Any, ...]]]
    ) -> tuple[set[Atom], list[tuple[str, str]]]:
        """Calls that can never be true in this state (reported, but for unreachable outcomes: returned)."""
        label = arrow(transition.from_, transition.to)
        where = {"mission": mission, "state": state.name, "transition": label}
        dead: set[Atom] = set()
        unreached: list[tuple[str, str]] = []
        limit = state.timeout
        behavior = self.system.behavior(state.behavior) if state.behavior else None
        if limit is None and behavior is not None:
            limit = behavior.timeout
        unknown = state.behavior is not None and behavior is None  # reported on the state; nothing to judge
        nested = self.system.mission(state.mission) if state.mission else None
        for name, args in dict.fromkeys(calls):
            atom: Atom = ("call", name, *args)
            if name == "timeout" and limit is None and not unknown:
                message = (
                    f"transition {label} waits for timeout(), but neither state {state.name!r} nor its behavior has"
                    " a timeout, so it never fires; set timeout= on the state or the behavior"
                )
                self.add(finding("timeout-never-fires", "warning", message, transition, **where))
            elif name == "signal" and self.system.plans and args[0] not in self.signals:
                known = ", ".join(sorted(self.signals)) or "none"
                message = f"transition {label} waits for signal {args[0]!r}, which no plan emits (signals: {known})"
                self.add(finding("unknown-signal", "error", message, transition, **where))
            elif name == "lost" and self.system.plans and args[0] not in self.agents:
                known = ", ".join(sorted(self.agents)) or "none"
                message = (
                    f"transition {label} waits for agent {args[0]!r} to be lost, but no plan has it (agents: {known})"
                )
                self.add(finding("unknown-agent", "error", message, transition, **where))
            elif name != "outcome":
                continue
            elif nested is None:
                if state.mission is None:  # a missing nested mission is reported on the state
                    message = f"transition {label} uses outcome(), but state {state.name!r} runs a behavior"
                    self.add(finding("outcome-not-nested", "error", message, transition, **where))
            elif args[0] not in nested.outcomes():
                message = (
                    f"transition {label} waits for outcome {args[0]!r}, which mission {nested.name!r} does not have"
                    f" (its finals: {', '.join(nested.outcomes()) or 'none'})"
                )
                self.add(finding("unknown-outcome", "error", message, transition, **where))
            elif args[0] not in self.outcomes(nested.name):
                unreached.append((str(args[0]), nested.name))
            else:
                continue
            dead.add(atom)
        return dead, unreached

    def _unshadowed(
        self,
        transition: Transition,
        live: list[Conjunction],
        earlier: list[tuple[Transition, list[Conjunction]]],
        where: dict[str, str],
    ) -> list[Conjunction]:
        """The live conjunctions no earlier transition takes first (document order, D14)."""
        label = where["transition"]
        taken = {c: next((t for t, conds in earlier if implies([c], conds)), None) for c in live}
        kept = [c for c, first in taken.items() if first is None]
        for conjunction, first in taken.items():
            if first is None:
                continue
            before = arrow(first.from_, first.to) + (f" (line {first.loc.line})" if first.loc else "")
            if not kept:
                if first.when.strip() == transition.when.strip():
                    reason = f"it has the same condition as {before}, which is tried first; remove one of them"
                else:
                    reason = (
                        f"it comes after {before}, whose condition {first.when!r} holds whenever"
                        f" {transition.when!r} does; put the more specific transition first, or merge them"
                    )
                message = f"transition {label} can never fire: {reason}"
                self.add(finding("shadowed-transition", "error", message, transition, **where))
                break
            message = (
                f"transition {label}: the part {describe(conjunction)!r} never makes it fire, since {before}"
                " is tried first and then holds too; drop that part or reorder the transitions"
            )
            self.add(finding("redundant-condition", "warning", message, transition, **where))
        return kept
