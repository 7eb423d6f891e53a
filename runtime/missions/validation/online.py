"""Off-line, then on-line (thesis §7.5): does a recorded run follow a path the off-line validation found?

§7.5 validates the missions off-line first (§5.4, the fake interaction of :mod:`runtime.missions.fake`)
and then runs them; a run whose states differ from every off-line episode shows a mission behaving
in a way the validation never saw. :func:`replay` compares one agent's recorded state sequence (the
behavior states it entered, nested missions unfolded, as the off-line episodes list them) with the
episodes of an off-line exploration of its mission:

- ``matched``: the off-line episode the run reproduces step for step (None: none does);
- ``divergence``: the first step of the run (``A -> B``) that no off-line episode takes, if any — a
  run can take only steps the validation took (a retry loop, say) without equalling any one episode.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass

from ckmconf.model import System

from ..fake import Coverage, explore
from ..recording import Event


@dataclass(frozen=True)
class Replay:
    """One agent's run against the off-line episodes of its mission (see the module docstring)."""

    agent: str
    mission: str
    online: tuple[str, ...]
    outcome: str | None
    matched: int | None
    divergence: str | None
    episodes: int

    @property
    def reproduced(self) -> bool:
        """The run's states are exactly those of one off-line episode."""
        return self.matched is not None

    def describe(self) -> str:
        """One line for a report."""
        steps = f"{len(self.online)} state(s)"
        if self.matched is not None:
            return f"{self.agent}: reproduces off-line episode {self.matched + 1} of {self.episodes} ({steps})"
        if self.divergence is not None:
            return f"{self.agent}: diverges from every off-line episode at {self.divergence} ({steps})"
        return f"{self.agent}: every step was taken off-line, but by no single episode ({steps})"


def online_states(events: Iterable[Event]) -> list[str]:
    """The behavior states an agent entered, in order (a nested mission's state is listed by its own states)."""
    states: list[str] = []
    for event in events:
        if event.kind == "enter" and event.get("nested") is None and isinstance(event.get("path"), str):
            path = str(event.get("path"))
            if not states or states[-1] != path:
                states.append(path)
    return states


def outcome_of(events: Iterable[Event]) -> str | None:
    """The final the agent's top mission ended in (its last ``end`` event's outcome), None without one."""
    outcome = None
    for event in events:
        if event.kind == "end":
            outcome = event.get("outcome")
    return outcome if isinstance(outcome, str) else None


def replay(
    system: System, mission: str, agent: str, events: Iterable[Event], coverage: Coverage | None = None
) -> Replay:
    """Compare ``agent``'s recorded ``events`` with the off-line episodes of ``mission`` (explored
    now unless ``coverage`` gives them)."""
    recorded = list(events)
    online = online_states(recorded)
    explored = coverage if coverage is not None else explore(system, mission)
    sequences = [list(episode.states) for episode in explored.episodes]
    matched = next((k for k, states in enumerate(sequences) if states == online), None)
    steps = {(a, b) for states in sequences for a, b in itertools.pairwise(states)}
    starts = {states[0] for states in sequences if states}
    divergence = next((f"{a} -> {b}" for a, b in itertools.pairwise(online) if (a, b) not in steps), None)
    if online and online[0] not in starts:
        divergence = f"the start, {online[0]}"
    return Replay(agent, mission, tuple(online), outcome_of(recorded), matched, divergence, len(sequences))
