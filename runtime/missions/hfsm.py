"""Missions as hierarchical finite state machines (thesis §5.2).

A mission is built from its ``<Mission>`` record: one initial state; states run a behavior or a
nested mission; one-way transitions fire on conditions (docs/decisions.md D9) over the state's
behavior (``done()``, ``failed()``, ``progress``), time (``timeout()``, ``elapsed``), the nested
mission's outcome (``outcome('x')``), plan signals (``signal('s')``), the other agents of the plan
(``lost('a')``: agent ``a`` is silent past the plan's ``lostAfter``, or has finished in a final
other than its success final) and the services the behavior uses (``alias.field``,
``performance``). The mission's output is its active state's.

Every step, from the top down: a state's transitions are tried in document order, the first that
holds fires (D14) — so an outer state's ``timeout()`` pre-empts whatever runs inside it — and
only if none fires does the step go down into the nested mission, or step the behavior (whose
fresh status is then tried against the state's transitions). A transition to a ``<Final>`` ends
that mission with that outcome; the parent sees it as ``outcome('name')`` and ``done()``.

Mission progress counts towards the first declared final (the success outcome by convention):
with D(s) the fewest transitions from s to it, a mission at state s whose own progress is p has
progress (D(initial) − D(s) + p) / D(initial), clamped to [0, 1] — a retry lowers it, as it
should. A nested state's progress is its mission's.

The engine is driven by ``step()`` on a clock it is given: real time in a live run, simulated
time in the off-line validation (the same code runs both).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from ckmconf.expressions import Condition, Environment, evaluate
from ckmconf.model import System
from ckmconf.model.missions import Mission, State, Transition

from .behaviors import Behavior, BehaviorStatus, ServiceHandle
from .composition import behavior_performance
from .hfsm_conditions import state_environment
from .signals import Signals, SignalSender


class Recorder(Protocol):
    """Where the engine writes its mission log (a :class:`runtime.missions.recording.RunRecorder`)."""

    def write(self, kind: str, **fields: Any) -> object:
        """Append one log record of ``kind`` with ``fields``."""


BehaviorFactory = Callable[[str, str, Callable[[], float]], Behavior]
"""(behavior name, state path, seconds-in-state clock) → the behavior to start for that state."""


class MissionError(RuntimeError):
    """A mission that cannot be built or run (unknown mission, behavior or state)."""


def distances_to_success(mission: Mission) -> dict[str, int]:
    """Fewest transitions from each state to the first declared final (absent: unreachable)."""
    if not mission.finals:
        return {}
    import networkx as nx  # type: ignore[import-untyped]  # here: ckm-run imports this module and rarely runs a mission

    graph = nx.DiGraph()
    graph.add_edges_from((t.from_, t.to) for t in mission.transitions)
    goal = mission.finals[0].name
    if goal not in graph:
        return {goal: 0}
    return dict(nx.single_source_shortest_path_length(graph.reverse(copy=False), goal))


class MissionRun:
    """One level of the HFSM (§5.2): a ``<Mission>`` record and its active ``<State>``."""

    def __init__(self, engine: MissionEngine, mission: Mission, path: str) -> None:
        self.engine, self.mission, self.path = engine, mission, path
        self.state: State | None = None
        self.entered = 0.0
        self.behavior: Behavior | None = None
        self.status = BehaviorStatus()
        self.child: MissionRun | None = None
        self.outcome: str | None = None
        self.finals = {f.name for f in mission.finals}
        self.distance = distances_to_success(mission)
        self.transitions = [
            (t, engine.condition(t, f"{mission.name}: {t.from_} -> {t.to}")) for t in mission.transitions
        ]

    # ------------------------------------------------------------------ states

    def state_path(self) -> str:
        """Slash path of the active state (``mission/…/state``); only valid while a state is active."""
        assert self.state is not None
        return f"{self.path}/{self.state.name}"

    def enter(self, name: str) -> None:
        """Enter state ``name`` (MissionError if absent): start its behavior or nested mission, record it."""
        state = self.mission.state(name)
        if state is None:
            raise MissionError(f"mission {self.mission.name!r} has no state {name!r}")
        engine = self.engine
        self.state, self.entered, self.status, self.behavior, self.child = (
            state,
            engine.now(),
            BehaviorStatus(),
            None,
            None,
        )
        path = self.state_path()
        engine.record(
            "enter", path=path, state=name, mission=self.mission.name, behavior=state.behavior, nested=state.mission
        )
        if state.mission is not None:
            nested = engine.system.mission(state.mission)
            if nested is None:
                raise MissionError(f"state {path} runs an unknown mission {state.mission!r}")
            self.child = MissionRun(engine, nested, path)
            self.child.enter(nested.initial)
        elif state.behavior is not None:
            entered = self.entered
            self.behavior = engine.factory(state.behavior, path, lambda: engine.now() - entered)
            self.behavior.context.demand(True)
            self.behavior.start()
        engine.emit(path, "entry")  # after the behavior's start, which may supply the signal's payload

    def exit(
        self, to: str | None, condition: str | None, reason: str, released: list[Callable[[], None]] | None = None
    ) -> None:
        """Leave the active state: stop its child and behavior, emit its ``done``/``exit`` signals, record it.

        The behavior stops asking for its topics at once, or, given ``released``, when the caller
        has entered the next state: a topic both read is then asked for throughout (D249).
        """
        if self.state is None:
            return
        if self.child is not None and self.child.outcome is None:
            self.child.exit(None, None, "stopped", released)
        if self.behavior is not None:
            self.behavior.stop()
            release = functools.partial(self.behavior.context.demand, False)
            if released is None:
                release()
            else:
                released.append(release)
        path = self.state_path()
        if self.status.done or (self.child is not None and self.child.outcome is not None):
            self.engine.emit(path, "done")
        self.engine.emit(path, "exit")
        detail = self.status.detail if self.behavior is not None and self.status.failed else None
        if detail:
            self.engine.failures.append(f"{path}: {detail}")
        self.engine.record("exit", path=path, state=self.state.name, mission=self.mission.name, to=to,
                           condition=condition, reason=reason, **({"detail": detail} if detail else {}))  # fmt: skip
        self.state, self.behavior, self.child = None, None, None

    # ------------------------------------------------------------------ stepping

    def step(self) -> None:
        """One top-down HFSM step (§5.2): try transitions, else step the nested mission or the behavior."""
        if self.outcome is not None or self.state is None:
            return
        if self._try_transitions():
            return
        if self.child is not None:
            self.child.step()
            if self.child.outcome is not None:
                self._try_transitions()
        elif self.behavior is not None:
            self.status = self.behavior.step()
            self._record_logs()
            self._try_transitions()

    def _record_logs(self) -> None:
        """What the behavior logged (``BehaviorContext.log``) goes into the recording."""
        events = self.behavior.context.events if self.behavior is not None else []
        while events:
            self.engine.record("log", path=self.state_path(), **events.pop(0))

    def _try_transitions(self) -> bool:
        assert self.state is not None
        env = self.engine.environment(self)
        if env is None:  # the engine holds this state (the off-line driver's dwell)
            return False
        for transition, condition in self.transitions:
            if transition.from_ == self.state.name and evaluate(condition, env):
                released: list[Callable[[], None]] = []
                self.exit(transition.to, transition.when, "transition", released)
                try:
                    if transition.to in self.finals:
                        self.outcome = transition.to
                        self.engine.record("outcome", mission=self.mission.name, path=self.path, outcome=transition.to)
                    else:
                        self.enter(transition.to)
                finally:
                    for release in released:
                        release()
                return True
        return False

    # ------------------------------------------------------------------ measures

    def own_progress(self) -> float:
        """Progress p of the active state: its nested mission's, else its behavior's, in [0, 1]."""
        if self.child is not None:
            return self.child.progress()
        return max(0.0, min(1.0, self.status.progress))

    def progress(self) -> float:
        """Mission progress (D(initial) − D(s) + p) / D(initial) towards the first final, in [0, 1]."""
        if self.outcome is not None:
            return 1.0 if self.mission.finals and self.outcome == self.mission.finals[0].name else 0.0
        start = self.distance.get(self.mission.initial)
        if not start or self.state is None:
            return 0.0
        here = self.distance.get(self.state.name, start)
        return max(0.0, min(1.0, (start - here + self.own_progress()) / start))

    def leaf(self) -> MissionRun:
        """The innermost run that has an active state (this one if no nested mission runs)."""
        return self.child.leaf() if self.child is not None and self.child.state is not None else self

    def elapsed(self) -> float:
        """Seconds (engine clock) since the active state was entered."""
        return self.engine.now() - self.entered

    def timed_out(self) -> bool:
        """True when the state's ``timeout`` (or its behavior's ``<Behavior timeout>``) has elapsed."""
        if self.state is None:
            return False
        limit = self.state.timeout
        if limit is None and self.state.behavior is not None:
            record = self.engine.system.behavior(self.state.behavior)
            limit = record.timeout if record is not None else None
        return limit is not None and self.elapsed() > limit

    def performance(self) -> float | None:
        """SPC (eq. 5.1) of the active behavior's services under this mission's matrix."""
        if self.behavior is None:
            return None
        matrix = self.engine.system.matrix(self.mission.composition) if self.mission.composition else None
        services = self.behavior.context.services
        return behavior_performance(self.engine.system, matrix, self.behavior.record, services, self.engine.related)


class MissionEngine:
    """Runs one agent's top mission as an HFSM (§5.2; see the module docstring)."""

    def __init__(
        self,
        system: System,
        mission: str,
        *,
        factory: BehaviorFactory,
        clock: Callable[[], float],
        agent: str = "agent",
        recorder: Recorder | None = None,
        signals: Signals | None = None,
        emitters: Mapping[tuple[str, str], str] | None = None,
        on_signal: Callable[[str, Any], None] | None = None,
        progress_period: float = 0.25,
        plan: str | None = None,
        signal_types: Mapping[str, str | None] | None = None,
        related: Callable[[str], ServiceHandle | None] | None = None,
        lost: Callable[[str], bool] | None = None,
    ) -> None:
        record = system.mission(mission)
        if record is None:
            known = ", ".join(m.name for m in system.missions) or "none"
            raise MissionError(f"no mission {mission!r} (missions: {known})")
        self.system, self.record_mission, self.agent = system, record, agent
        self.factory, self.clock, self.recorder = factory, clock, recorder
        self.signals = signals or Signals()
        self._sender = SignalSender(
            self.signals,
            agent,
            emitters=emitters,
            signal_types=signal_types,
            types={t.name: t for t in system.message_types},
            on_signal=on_signal,
            record=self.record,
        )
        self.progress_period = progress_period
        self.plan = plan
        self._related = related  # the services eq. 5.1 weighs that a behavior does not use itself
        self._lost = lost  # lost('agent'): the plan agent's runner knows (None: no plan, never lost)
        self._stopping = False
        self._start = 0.0
        self._last_progress = -1e9
        self.failures: list[str] = []  # "state path: detail" of each behavior that failed, in order
        self.top = MissionRun(self, record, record.name)

    # ------------------------------------------------------------------ services for MissionRun

    def now(self) -> float:
        """Seconds on the engine's clock since :meth:`start`."""
        return self.clock() - self._start

    def record(self, kind: str, **fields: Any) -> None:
        """Write one mission-log record if a recorder is attached."""
        if self.recorder is not None:
            self.recorder.write(kind, **fields)

    def related(self, ref: str) -> ServiceHandle | None:
        """A service the composition weighs though the active behavior does not use it (eq. 5.1)."""
        return self._related(ref) if self._related is not None else None

    def agent_lost(self, agent: str) -> bool:
        """``lost('agent')`` (§5.3): the plan's agent is lost or ended in failure (False without a plan)."""
        return bool(self._lost(agent)) if self._lost is not None else False

    def condition(self, transition: Transition, where: str) -> Condition:
        """The transition's condition, parsed when its record was read; a MissionError if it does not parse."""
        error = transition.condition_error
        if error is not None:
            raise MissionError(f"{where}: {error}")
        return transition.condition

    def emit(self, path: str, when: str) -> None:
        """Send the plan signal declared on ``path`` for ``when`` (entry/done/exit), payload type-checked (§5.3)."""
        self._sender.emit(path, when, self.now(), self._stopping)

    def environment(self, run: MissionRun) -> Environment | None:
        """What ``run``'s transitions are evaluated against (None: try none this step)."""
        return state_environment(run, self.signals.received, self.agent_lost)

    # ------------------------------------------------------------------ driving

    def start(self) -> None:
        """Start the clock, record ``start`` and enter the top mission's initial state."""
        self._start = self.clock()
        self.record("start", mission=self.record_mission.name, plan=self.plan, wall=time.time())
        self.top.enter(self.record_mission.initial)

    @property
    def outcome(self) -> str | None:
        """Name of the final the top mission ended in, None while it runs."""
        return self.top.outcome

    def active_path(self) -> str | None:
        """Slash path of the innermost active state, None when nothing is active."""
        leaf = self.top.leaf()
        return leaf.state_path() if leaf.state is not None else None

    def step(self) -> str | None:
        """One mission period; the top mission's outcome once it has ended."""
        if self.top.outcome is None:
            self.top.step()
            now = self.now()
            if now - self._last_progress >= self.progress_period or self.top.outcome is not None:
                self._last_progress = now
                leaf = self.top.leaf()
                if self.top.outcome is not None:  # the final point of the progress curve
                    self.record("progress", path=self.top.path, progress=self.top.progress(), performance=None,
                                mission_progress=self.top.progress())  # fmt: skip
                elif leaf.state is not None:
                    self.record("progress", path=leaf.state_path(), progress=leaf.own_progress(),
                                performance=leaf.performance(), mission_progress=self.top.progress())  # fmt: skip
            if self.top.outcome is not None:
                self.record("end", outcome=self.top.outcome, wall=time.time())
        return self.top.outcome

    def stop(self, reason: str = "stopped") -> None:
        """Abort a running mission: exit every active state with ``reason`` and record ``end``."""
        if self.top.outcome is None and self.top.state is not None:
            self._stopping = True
            self.top.exit(None, None, reason)
            self.record("end", outcome=reason, wall=time.time())
