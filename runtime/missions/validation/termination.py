"""Graph checks of a mission HFSM (thesis §5.4, §7.5.1: "continuity and terminality"; docs/decisions.md).

On the graph of the transitions that can fire (built by :mod:`.static`): a state not reachable
from the initial one is an error, a final one a warning; a reachable state with no transition
that can fire is a ``dead-end``; one from which no final is reachable (a loop with no exit, or a
path into a dead end) is ``non-terminating``. **Endings**: for each way a state can end (its
behavior done or failed, its nested mission in one of its reachable finals) some transition
should be *sure* to fire afterwards, otherwise ``unhandled-done`` / ``unhandled-failure`` /
``unhandled-outcome`` warnings.
"""

from __future__ import annotations

from typing import Protocol

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.model import Final, Mission, State, System, Transition

from .conditions import Conjunction, Interval, Literal
from .findings import Finding, finding


class Checker(Protocol):
    """What the graph checks need of the mission checker (:class:`runtime.missions.validation.static`)."""

    @property
    def system(self) -> System:
        """The system the missions belong to."""

    @property
    def reached(self) -> dict[str, set[str]]:
        """Per mission analysed, the finals reachable from its initial state (written here)."""

    def add(self, *found: Finding) -> None:
        """Report findings."""

    def outcomes(self, name: str) -> set[str]:
        """Reachable finals of a nested mission."""


def check_graph(
    checker: Checker,
    mission: Mission,
    graph: nx.DiGraph,
    states: dict[str, State],
    finals: dict[str, Final],
    by_source: dict[str, list[tuple[Transition, list[Conjunction]]]],
    opaque: set[str],
) -> None:
    """Reachability, dead ends, termination and endings of ``mission`` on ``graph``; records its reachable finals."""
    name = mission.name
    if not finals:
        message = f"mission {name!r} has no final state, so it can never end; add a <Final>"
        checker.add(finding("no-final", "error", message, mission, mission=name))
    if mission.initial not in states:
        known = ", ".join(states) or "none"
        message = f"mission {name!r} starts in {mission.initial!r}, which is not one of its states ({known})"
        checker.add(finding("missing-initial", "error", message, mission, mission=name))
        checker.reached[name] = set()
        return
    reachable = nx.descendants(graph, mission.initial) | {mission.initial}
    checker.reached[name] = {f for f in finals if f in reachable}
    finishing = set(finals).union(*(nx.ancestors(graph, f) for f in finals))
    for state in mission.states:
        if state.name not in reachable:
            message = (
                f"state {state.name!r} can never be reached from the initial state {mission.initial!r}:"
                " add a transition into it, or remove it"
            )
            checker.add(finding("unreachable-state", "error", message, state, mission=name, state=state.name))
        elif graph.out_degree(state.name) == 0:
            why = "has no transition" if state.name not in by_source else "has no transition that can ever fire"
            message = f"state {state.name!r} {why}: once entered, mission {name!r} never ends; add a way out"
            checker.add(finding("dead-end", "error", message, state, mission=name, state=state.name))
        elif state.name not in finishing and finals:
            checker.add(_non_terminating(mission, graph, state, finishing))
        elif state.name not in opaque:
            check_endings(checker, mission, state, [c for _, conds in by_source[state.name] for c in conds])
    for final in mission.finals:
        if final.name not in reachable:
            message = f"final state {final.name!r} of mission {name!r} can never be reached; add a transition to it"
            checker.add(finding("unreachable-final", "warning", message, final, mission=name))


def _non_terminating(mission: Mission, graph: nx.DiGraph, state: State, finishing: set[str]) -> Finding:
    """The ``non-terminating`` finding of ``state``: the loop it is caught in, or the states that cannot finish."""
    loop = next((c for c in nx.strongly_connected_components(graph) if state.name in c), {state.name})
    if len(loop) > 1 or graph.has_edge(state.name, state.name):
        members = ", ".join(sorted(loop))
        detail = f"it loops through {members} and no transition leaves that loop towards a final state"
    else:
        ahead = sorted(nx.descendants(graph, state.name) - finishing)
        detail = f"every way on leads to states that cannot finish ({', '.join(ahead)})"
    message = f"no final state of mission {mission.name!r} can be reached from state {state.name!r}: {detail}"
    return finding("non-terminating", "error", message, state, mission=mission.name, state=state.name)


def check_endings(checker: Checker, mission: Mission, state: State, conjunctions: list[Conjunction]) -> None:
    """Warn for each way ``state`` can end after which no transition (``conjunctions``) is sure to fire."""
    timeout = state.timeout is not None
    if state.behavior is not None:
        behavior = checker.system.behavior(state.behavior)
        timeout = timeout or (behavior is not None and behavior.timeout is not None)
        endings: list[tuple[str, str | None]] = [("done", None), ("failed", None)]
    elif state.mission is not None and checker.system.mission(state.mission) is not None:
        endings = [("outcome", x) for x in sorted(checker.outcomes(state.mission))]
    else:
        return
    for ending, outcome in endings:
        if any(all(_sure(lit, ending, outcome, timeout) for lit in c) for c in conjunctions):
            continue
        if ending == "outcome":
            kind, what, fix = (
                "unhandled-outcome",
                f"mission {state.mission!r} ends in {outcome!r}",
                f"outcome('{outcome}')",
            )
        elif ending == "done":
            kind, what, fix = "unhandled-done", f"behavior {state.behavior!r} is done", "done()"
        else:
            kind, what, fix = "unhandled-failure", f"behavior {state.behavior!r} fails", "failed()"
        message = (
            f"when {what}, no transition out of state {state.name!r} is sure to fire, so mission"
            f" {mission.name!r} may hang there; add a transition on {fix} or timeout()"
        )
        checker.add(finding(kind, "warning", message, state, mission=mission.name, state=state.name))


def _sure(literal: Literal, ending: str, outcome: str | None, timeout: bool) -> bool:
    """Whether a literal is bound to hold, sooner or later, once a state has ended this way."""
    atom = literal.atom
    if atom == ("call", "timeout"):
        return literal.positive and timeout
    if atom[0] == "cmp" and atom[1] == "elapsed" and isinstance(atom[2], Interval):
        return literal.positive and atom[2].high == float("inf")  # time only grows
    if atom[0] != "call":
        return False
    holds = {
        "done": ending in ("done", "outcome"),
        "failed": ending == "failed",
        "outcome": ending == "outcome" and atom[2:] == (outcome,),
    }.get(str(atom[1]))
    return holds is not None and holds == literal.positive
