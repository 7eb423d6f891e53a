"""Off-line mission run with the "fake interaction" module (thesis §5.4, §7.5.1, Fig. 7.21).

The mission runs on the real HFSM engine in simulated time, its behaviors replaced by scripted
ones (progress ramps over ``dwell`` simulated seconds) and its services by simulated ones that
meet every requirement. A ``signal('s')`` is taken as true only for a signal some agent of a plan can send and that is
in no deadlock (:func:`~runtime.missions.validation.plans.assumable_signals`); with no plan in
the system every signal counts as an outside input. ``lost('agent')`` is always an outside input
(any agent's process may die, D177): the solver sets it as it sets any call. The fake interaction
decides, when a state is entered (or when its
nested mission has ended), which transition it will take, and after the dwell makes exactly that
transition's condition the first that holds (:mod:`runtime.missions.solver`). Episodes are
repeated from the initial state, each steering towards transitions not yet covered: an
uncovered transition that can fire is taken first; otherwise the one leading closest to
uncovered ones (inside nested missions too); otherwise the one closest to the success final.
A nested mission is steered towards the outcomes the parent still needs.

Reported: state and transition coverage, each episode's state sequence and outcome, and every
transition no episode could fire (its condition can never be the first to hold, or its state is
never reached) — with the transition's file:line. Runs are recorded like live ones, one run
directory per episode, so ``ckm-mission report`` draws Fig. 7.21 from them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import Mission, Transition

from ..resources.api import Bounds
from .behaviors import Behavior, BehaviorContext, BehaviorStatus
from .hfsm import MissionEngine, MissionRun, Recorder
from .solver import Key, environment, solve

TKey = tuple[str, int]  # (mission, index of the transition in the mission)


class SimulatedService:
    """A service that is running and meets whatever the behavior requires of it."""

    def __init__(self, ref: str) -> None:
        self.ref = ref
        self._requirements: tuple[Bounds, ...] = ()
        self.parameters: dict[str, Any] = {}

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        """Keep the parameters and the requirements whose intervals :meth:`measures` will meet."""
        self.parameters.update(parameters)
        self._requirements = requirements

    def output(self, name: str) -> Any:
        """No outputs off-line: conditions on service fields are steered by the solver instead."""
        return None

    def measures(self) -> dict[str, float]:
        """One value inside each requested quality interval, so every ``<Require>`` is met."""
        values = {}
        for r in self._requirements:  # a value inside each requested interval (bounds are inclusive)
            if r.lower is not None and r.upper is not None:
                values[r.measure] = (r.lower + r.upper) / 2
            elif r.lower is not None:
                values[r.measure] = r.lower
            elif r.upper is not None:
                values[r.measure] = r.upper / 2 if r.upper > 0 else r.upper
        return values

    def samples(self, measure: str) -> list[float]:
        """Ten copies of the measure's value (a steady service state for eq. 5.1)."""
        value = self.measures().get(measure)
        return [] if value is None else [value] * 10

    def running(self) -> bool:
        """Always running: a simulated service never goes silent."""
        return True


class ScriptedBehavior(Behavior):
    """Progress ramps from 0 to 1 over ``dwell`` simulated seconds; the fake interaction decides the rest."""

    def __init__(self, record: BehaviorRecord, context: BehaviorContext, dwell: float) -> None:
        self.record, self.name, self.context, self.params = record, record.name, context, {}
        self.dwell = dwell

    def step(self) -> BehaviorStatus:
        """Progress ramps linearly to 1 over ``dwell`` simulated seconds; never done or failed by itself."""
        return BehaviorStatus(progress=min(1.0, self.context.now() / self.dwell))


@dataclass
class Episode:
    """One off-line run from the initial state: the state paths it visited, its outcome, end time and problem."""

    states: list[str] = field(default_factory=list)
    outcome: str | None = None
    time: float = 0.0
    problem: str | None = None


@dataclass
class Coverage:
    """State and transition counts over all episodes, keyed by (mission, state) and (mission, transition index)."""

    states: dict[tuple[str, str], int]
    transitions: dict[TKey, int]
    episodes: list[Episode]
    missions: dict[str, Mission]

    def share(self) -> tuple[float, float]:
        """Shares of states and of transitions visited at least once, each in [0, 1]."""
        s = sum(1 for v in self.states.values() if v) / max(1, len(self.states))
        t = sum(1 for v in self.transitions.values() if v) / max(1, len(self.transitions))
        return s, t

    def uncovered(self) -> list[tuple[Mission, Transition]]:
        """The transitions no episode fired, with their mission (reported with file:line, §5.4)."""
        return [(self.missions[m], self.missions[m].transitions[i]) for (m, i), n in self.transitions.items() if not n]


class FakeInteraction(MissionEngine):
    """The engine with conditions answered by the fake interaction (§5.4, Fig. 7.21; see the module docstring)."""

    def __init__(
        self, system: System, mission: str, coverage: Coverage, dwell: float, assumable: set[str] | None = None,
        **kwargs: Any,
    ) -> None:  # fmt: skip
        self.coverage, self.dwell = coverage, dwell
        self.assumable = assumable  # signals signal() may be taken as true for (None: every one)
        self.plans: dict[int, tuple[int, dict[Key, Any]] | None] = {}
        self.wanted: dict[int, set[str]] = {}
        self.problem: str | None = None
        kwargs.setdefault("related", SimulatedService)  # eq. 5.1's other services: running and compliant
        super().__init__(system, mission, factory=self._behavior, **kwargs)

    def _behavior(self, behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        record = self.system.behavior(behavior)
        if record is None:
            raise KeyError(f"state {path}: no behavior {behavior!r}")
        services = {u.alias: SimulatedService(u.service) for u in record.uses}
        context = BehaviorContext(services=services, inputs={}, outputs={}, now=now)
        return ScriptedBehavior(record, context, self.dwell)

    # ------------------------------------------------------------------ steering

    def environment(self, run: MissionRun) -> Any:
        """Condition environment steering ``run`` to the transition planned for it, after the dwell."""
        assert run.state is not None
        nested = run.child is not None
        if nested and run.child is not None and run.child.outcome is None:
            self.wanted[id(run.child)] = self._wanted_outcomes(run)
            return None
        if not nested and run.elapsed() < self.dwell:
            return None
        key = id(run)
        if key not in self.plans:
            self.plans[key] = self._choose(run)
        plan = self.plans[key]
        if plan is None:
            self.problem = f"{run.state_path()}: no transition can fire here"
            return None
        index, values = plan
        self.coverage.transitions[(run.mission.name, index)] += 1
        del self.plans[key]
        return environment(values)

    def record(self, kind: str, **fields: Any) -> None:
        """Count the entered states and reached finals into :attr:`coverage`, then record as usual."""
        if kind == "enter":
            self.coverage.states[(fields["mission"], fields["state"])] += 1
        elif kind == "outcome":
            self.coverage.states[(fields["mission"], fields["outcome"])] += 1
        super().record(kind, **fields)

    def _fixed(self, run: MissionRun) -> dict[Key, Any]:
        fixed: dict[Key, Any] = {}
        if self.assumable is not None:  # a signal no agent of a plan can send is never received
            for _, condition in run.transitions:  # the conditions parsed at load
                for function, args in condition.calls:
                    if function == "signal" and args[0] not in self.assumable:
                        fixed[("call", "signal", args[0])] = False
        if run.child is not None:
            fixed[("call", "done")] = run.child.outcome is not None
            for name in run.child.finals:
                fixed[("call", "outcome", name)] = run.child.outcome == name
        return fixed

    def _options(self, run: MissionRun, fixed_outcome: str | None = None) -> list[tuple[int, dict[Key, Any]]]:
        assert run.state is not None
        indices = [i for i, t in enumerate(run.mission.transitions) if t.from_ == run.state.name]
        conditions = [run.transitions[i][1] for i in indices]
        fixed = self._fixed(run)
        if fixed_outcome is not None and run.child is not None:
            fixed[("call", "done")] = True
            fixed.update({("call", "outcome", n): n == fixed_outcome for n in run.child.finals})
        options = []
        for position, index in enumerate(indices):
            values = solve(conditions, position, fixed)
            if values is not None:
                options.append((index, values))
        return options

    def _choose(self, run: MissionRun) -> tuple[int, dict[Key, Any]] | None:
        options = self._options(run)
        if not options:
            return None
        mission = run.mission
        uncovered = [o for o in options if not self.coverage.transitions[(mission.name, o[0])]]
        if uncovered:
            return uncovered[0]
        wanted = self.wanted.get(id(run), set())

        def score(option: tuple[int, dict[Key, Any]]) -> tuple[float, float]:
            target = mission.transitions[option[0]].to
            if target in run.finals:
                return (0.0 if target in wanted else math.inf, 0.0 if target == mission.finals[0].name else 1e6)
            return (self._gain(mission, target, set()), float(run.distance.get(target, 10**6)))

        return min(options, key=score)

    def _gain(self, mission: Mission, start: str, seen: set[str]) -> float:
        """Fewest transitions from ``start`` to something uncovered in ``mission`` (nested included)."""
        seen = seen | {mission.name}
        graph = nx.DiGraph()
        graph.add_node(start)
        graph.add_edges_from((t.from_, t.to) for t in mission.transitions)
        uncovered = {
            t.from_ for i, t in enumerate(mission.transitions) if not self.coverage.transitions[(mission.name, i)]
        }
        # Breadth-first: the states by increasing distance, so the first one that leads on is the nearest.
        for state, distance in nx.single_source_shortest_path_length(graph, start).items():
            if state in uncovered:
                return float(distance)
            record = mission.state(state)
            if record is not None and record.mission and record.mission not in seen:
                nested = self.system.mission(record.mission)
                if nested is not None and self._gain(nested, nested.initial, seen) < math.inf:
                    return float(distance)
        return math.inf

    def _wanted_outcomes(self, run: MissionRun) -> set[str]:
        """Outcomes of ``run``'s nested mission after which the parent gets closest to something uncovered."""
        assert run.child is not None
        value: dict[str, float] = {}
        for outcome in run.child.finals:
            best = math.inf
            for index, _ in self._options(run, fixed_outcome=outcome):
                transition = run.mission.transitions[index]
                if not self.coverage.transitions[(run.mission.name, index)]:
                    best = 0.0
                elif transition.to not in run.finals:
                    best = min(best, 1 + self._gain(run.mission, transition.to, set()))
            value[outcome] = best
        lowest = min(value.values(), default=math.inf)
        return {o for o, v in value.items() if v == lowest and v < math.inf}


class SimulatedClock:
    """Simulated seconds, advanced by the driver."""

    def __init__(self) -> None:
        self.time = 0.0

    def __call__(self) -> float:
        """Current simulated time in seconds (advanced by the explorer, not by the wall clock)."""
        return self.time


def missions_below(system: System, name: str) -> dict[str, Mission]:
    """``name`` and every mission it nests, by name."""
    found: dict[str, Mission] = {}
    stack = [name]
    while stack:
        mission = system.mission(stack.pop())
        if mission is None or mission.name in found:
            continue
        found[mission.name] = mission
        stack.extend(s.mission for s in mission.states if s.mission)
    return found


def explore(
    system: System,
    mission: str,
    *,
    step: float = 0.1,
    horizon: float = 3600.0,
    dwell: float = 1.0,
    max_episodes: int | None = None,
    recorder: Callable[[int, Callable[[], float]], Recorder | None] | None = None,
    signals: set[str] | None = None,
) -> Coverage:
    """Run episodes until every transition is covered or an episode covers nothing new twice.

    ``signals``: the plan signals ``signal()`` may be taken as received for (None: any), from
    :func:`~runtime.missions.validation.plans.assumable_signals`.
    """
    missions = missions_below(system, mission)
    coverage = Coverage(
        states={
            (m.name, s): 0
            for m in missions.values()
            for s in [*(x.name for x in m.states), *(f.name for f in m.finals)]
        },
        transitions={(m.name, i): 0 for m in missions.values() for i in range(len(m.transitions))},
        episodes=[],
        missions=missions,
    )
    limit = max_episodes or 2 * len(coverage.transitions) + 5
    stale = 0
    for number in range(1, limit + 1):
        before = sum(1 for v in coverage.transitions.values() if v)
        clock = SimulatedClock()
        engine = FakeInteraction(
            system, mission, coverage, dwell, signals, clock=clock, agent=f"{mission}#{number}",
            recorder=recorder(number, clock) if recorder else None,
        )  # fmt: skip
        episode = Episode()
        engine.start()
        while engine.outcome is None and clock.time < horizon and engine.problem is None:
            clock.time += step
            path = engine.active_path()
            engine.step()
            if path is not None and (not episode.states or episode.states[-1] != path):
                episode.states.append(path)
        episode.outcome, episode.time, episode.problem = engine.outcome, clock.time, engine.problem
        if engine.outcome is None:
            episode.problem = episode.problem or f"no final state reached within {horizon:g} s (simulated)"
            engine.stop("timeout")
        coverage.episodes.append(episode)
        after = sum(1 for v in coverage.transitions.values() if v)
        if after == len(coverage.transitions):
            break
        stale = stale + 1 if after == before else 0
        if stale >= 2:
            break
    return coverage


def record_into(run_dir: Path) -> Callable[[int, Callable[[], float]], Recorder]:
    """A recorder factory writing each episode to ``run_dir/episode-N`` (simulated clock)."""
    from .recording import RunRecorder

    def make(number: int, clock: Callable[[], float]) -> Recorder:
        return RunRecorder(run_dir / f"episode-{number}", "validation", clock=clock)

    return make
