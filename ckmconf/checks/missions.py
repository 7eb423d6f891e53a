"""Semantic checks of behaviors, composition matrices, missions and plans (missions.xsd, thesis ch. 5)."""

from __future__ import annotations

from ..model import Agent, Behavior, CompositionMatrix, Dependency, Mission, Plan, Signal, State, System, Transition
from .report import Reporter, missing
from .resources import check_bounds, check_value
from .scope import Scope

_TOLERANCE = 1e-6


def check_missions(system: System, scope: Scope, report: Reporter) -> None:
    """Check behaviors, composition matrices, missions and plans (missions.xsd, ch. 5): names, references."""
    report.unique(system.behaviors, "behavior", "the system")
    report.unique(system.matrices, "composition matrix", "the system")
    report.unique(system.missions, "mission", "the system")
    report.unique(system.plans, "plan", "the system")
    for behavior in system.behaviors:
        _check_behavior(behavior, scope, report)
    for matrix in system.matrices:
        _check_matrix(matrix, scope, report)
    for mission in system.missions:
        _check_mission(mission, system, scope, report)
    _check_nesting(system, report)
    for plan in system.plans:
        _check_plan(plan, system, scope, report)
    _check_randomise(system, report)


def _check_behavior(behavior: Behavior, scope: Scope, report: Reporter) -> None:
    where = f"behavior {behavior.name!r}"
    if behavior.progress == "untraceable" and behavior.timeout is None:
        report.error(
            behavior, "an untraceable behavior needs a timeout so the mission cannot hang (§5.1.2)", "progress"
        )
    report.unique(behavior.uses, "service alias", where, key="alias")
    for uses in behavior.uses:
        found = scope.services.get(uses.service)
        if found is None:
            report.error(uses, missing("service", uses.service, "any SmartResource", scope.services), "service")
            continue
        _, service = found
        parameters = {p.name: p for p in service.parameters}
        for configure in uses.configure:
            parameter = parameters.get(configure.parameter)
            if parameter is None:
                report.error(
                    configure,
                    missing("parameter", configure.parameter, f"service {uses.service}", parameters),
                    "parameter",
                )
                continue
            problem = check_value(parameter, configure.value)
            if problem:
                report.error(configure, f"value {configure.value!r} for {configure.parameter} {problem}", "value")
        measures = service.measure_names()
        for require in uses.requires:
            if require.measure not in measures:
                report.error(
                    require, missing("quality measure", require.measure, f"service {uses.service}", measures), "measure"
                )
            check_bounds(require, require.lower, require.upper, report)
    for port in (*behavior.inputs, *behavior.outputs):
        if (port.topic is None) == (port.signal is None):
            report.error(port, "give either a topic or a signal")
        elif port.topic is not None and scope.topic(None, port.topic) is None:
            report.error(port, missing("external topic", port.topic, "the system", scope.external), "topic")
        elif port.signal is not None and scope.system.plans and port.signal not in scope.signals:
            report.error(port, missing("signal", port.signal, "any plan", scope.signals), "signal")


def _check_matrix(matrix: CompositionMatrix, scope: Scope, report: Reporter) -> None:
    report.unique(matrix.services, "service", f"composition matrix {matrix.name!r}", key="ref")
    for entry in matrix.services:
        if entry.ref not in scope.services:
            report.error(entry, missing("service", entry.ref, "any SmartResource", scope.services), "ref")
    n = len(matrix.services)
    if len(matrix.rows) != n:
        report.error(matrix, f"matrix has {len(matrix.rows)} rows for {n} services; it must be {n}×{n}")
        return
    bad = [(i, row) for i, row in enumerate(matrix.rows, start=1) if len(row.values) != n]
    for index, row in bad:
        report.error(row, f"row {index} has {len(row.values)} values; it must have {n}")
    if bad:
        return
    if matrix.rule == "strict":
        for index, row in enumerate(matrix.rows, start=1):
            if abs(sum(row.values) - 1) > _TOLERANCE:
                report.error(row, f'row {index} sums to {sum(row.values):g}, not 1 (rule="strict", eq. 5.1)')
        for column in range(n):
            total = sum(row.values[column] for row in matrix.rows)
            if abs(total - 1) > _TOLERANCE:
                report.error(matrix, f'column {column + 1} sums to {total:g}, not 1 (rule="strict", eq. 5.1)', "rule")
    else:
        for index, row in enumerate(matrix.rows, start=1):
            if sum(row.values) <= 0:
                report.error(
                    row, f'row {index} is all zeros; with rule="normalize" every service must depend on something'
                )


def _check_mission(mission: Mission, system: System, scope: Scope, report: Reporter) -> None:
    where = f"mission {mission.name!r}"
    report.unique([*mission.states, *mission.finals], "state", where)
    states = {s.name: s for s in mission.states}
    finals = {f.name for f in mission.finals}
    if mission.initial not in states:
        if mission.initial in finals:
            report.error(mission, f"the initial state {mission.initial!r} is a final state", "initial")
        else:
            report.error(mission, missing("state", mission.initial, where, states), "initial")
    behaviors = [b.name for b in system.behaviors]
    missions = [m.name for m in system.missions]
    for state in mission.states:
        if (state.behavior is None) == (state.mission is None):
            report.error(state, "a state runs either a behavior or a mission (give exactly one)")
        elif state.behavior is not None and state.behavior not in behaviors:
            report.error(state, missing("behavior", state.behavior, "the system", behaviors), "behavior")
        elif state.mission is not None and state.mission not in missions:
            report.error(state, missing("mission", state.mission, "the system", missions), "mission")
    for transition in mission.transitions:
        if transition.from_ in finals:
            report.error(transition, f"no transition may leave the final state {transition.from_!r}", "from")
        elif transition.from_ not in states:
            report.error(transition, missing("state", transition.from_, where, states), "from")
        if transition.to not in states and transition.to not in finals:
            report.error(transition, missing("state", transition.to, where, [*states, *finals]), "to")
        source = states.get(transition.from_)
        if source is not None:
            _check_condition(transition, source, system, scope, report)
    _check_composition(mission, system, report)


def _plan_agents(system: System) -> list[str]:
    """The agents of every plan: what ``lost('agent')`` may name (§5.3)."""
    return sorted({a.name for plan in system.plans for a in plan.agents})


def _check_condition(transition: Transition, state: State, system: System, scope: Scope, report: Reporter) -> None:
    error = transition.condition_error  # parsed once, when the record was read
    if error is not None:
        report.error(transition, str(error), "when", error.column)
        return
    condition = transition.condition
    behavior = system.behavior(state.behavior) if state.behavior else None
    nested = system.mission(state.mission) if state.mission else None
    for name, args in condition.calls:
        if name == "outcome":
            if nested is None:
                report.error(
                    transition, f"outcome() is for states that run a mission; {state.name!r} runs a behavior", "when"
                )
            elif args[0] not in nested.outcomes():
                report.error(
                    transition, missing("outcome", str(args[0]), f"mission {nested.name!r}", nested.outcomes()), "when"
                )
        elif name == "signal" and system.plans and args[0] not in scope.signals:
            report.error(transition, missing("signal", str(args[0]), "any plan", scope.signals), "when")
        elif name == "lost" and system.plans and args[0] not in (agents := _plan_agents(system)):
            report.error(transition, missing("agent", str(args[0]), "any plan", agents), "when")
        elif name == "timeout" and state.timeout is None and (behavior is None or behavior.timeout is None):
            report.error(
                transition,
                f"timeout() can never fire: neither state {state.name!r} nor its behavior has a timeout",
                "when",
            )
    for alias, field in condition.attributes:
        uses = {u.alias: u for u in behavior.uses} if behavior is not None else {}
        found = uses.get(alias)
        if found is None:
            report.error(
                transition, missing("service alias", alias, f"the behavior of state {state.name!r}", uses), "when"
            )
            continue
        provided = scope.services.get(found.service)
        if provided is None:
            continue
        _, service = provided
        fields = [p.name for p in service.outputs] + [m.name for m in service.measures]
        if field not in fields:
            report.error(transition, missing("output or measure", field, f"service {found.service}", fields), "when")


def _check_composition(mission: Mission, system: System, report: Reporter) -> None:
    if mission.composition is None:
        return
    matrix = system.matrix(mission.composition)
    if matrix is None:
        report.error(
            mission,
            missing("composition matrix", mission.composition, "the system", [m.name for m in system.matrices]),
            "composition",
        )
        return
    listed = set(matrix.refs())
    for state in mission.states:
        behavior = system.behavior(state.behavior) if state.behavior else None
        if behavior is None:
            continue
        for uses in behavior.uses:
            if uses.service not in listed:
                message = f"service {uses.service} (used by behavior {behavior.name!r})"
                report.error(state, f"{message} is missing from composition matrix {matrix.name!r}", "behavior")


def _check_nesting(system: System, report: Reporter) -> None:
    """A mission must not contain itself through nested states."""
    graph = {m.name: [s for s in m.states if s.mission] for m in system.missions}
    for mission in system.missions:
        for state in graph.get(mission.name, []):
            if state.mission is not None and _nests(graph, state.mission, mission.name):
                report.error(
                    state, f"mission {mission.name!r} would contain itself through state {state.name!r}", "mission"
                )


def _nests(graph: dict[str, list[State]], start: str, goal: str) -> bool:
    todo, seen = [start], set()
    while todo:
        current = todo.pop()
        if current == goal:
            return True
        if current in seen:
            continue
        seen.add(current)
        todo.extend(s.mission for s in graph.get(current, []) if s.mission)
    return False


def resolve_state(system: System, mission_name: str, path: str) -> State | None:
    """The state at a nested path such as Navigation/NAV inside a mission, or None."""
    mission = system.mission(mission_name)
    state: State | None = None
    for step in path.split("/"):
        if mission is None:
            return None
        state = mission.state(step)
        if state is None:
            return None
        mission = system.mission(state.mission) if state.mission else None
    return state


def _waits_for(system: System, mission_name: str, path: str, signal: str) -> bool:
    """Whether the state at ``path`` uses ``signal`` in a transition or as a behavior input."""
    state = resolve_state(system, mission_name, path)
    if state is None:
        return True  # reported elsewhere
    parent_path, _, _ = path.rpartition("/")
    parent = system.mission(mission_name)
    if parent_path:
        holder = resolve_state(system, mission_name, parent_path)
        parent = system.mission(holder.mission) if holder and holder.mission else None
    behavior = system.behavior(state.behavior) if state.behavior else None
    if behavior is not None and any(port.signal == signal for port in behavior.inputs):
        return True
    for transition in parent.transitions if parent else ():
        if (
            transition.from_ == state.name
            and transition.condition_error is None
            and ("signal", (signal,)) in transition.condition.calls
        ):
            return True
    return False


def _check_plan(plan: Plan, system: System, scope: Scope, report: Reporter) -> None:
    where = f"plan {plan.name!r}"
    report.unique(plan.agents, "agent", where)
    report.unique(plan.signals, "signal", where)
    agents = {a.name: a for a in plan.agents}
    for agent in plan.agents:
        if system.node(agent.node) is None:
            report.error(agent, missing("node", agent.node, "the system", [n.name for n in system.nodes]), "node")
        if system.mission(agent.mission) is None:
            report.error(
                agent, missing("mission", agent.mission, "the system", [m.name for m in system.missions]), "mission"
            )
    signals = {s.name: s for s in plan.signals}

    def agent_state(record: Signal | Dependency) -> Agent | None:
        """The agent a signal or dependency names (checked with that state of its mission)."""
        agent = agents.get(record.agent)
        if agent is None:
            report.error(record, missing("agent", record.agent, where, agents), "agent")
        elif system.mission(agent.mission) and resolve_state(system, agent.mission, record.state) is None:
            report.error(
                record,
                f"state {record.state!r} does not exist in mission {agent.mission!r} of agent {agent.name!r}",
                "state",
            )
        return agent

    for signal in plan.signals:
        agent_state(signal)
        if signal.type is not None and not scope.type_exists(signal.type):
            report.error(signal, missing("message type", signal.type, "the system", scope.type_names()), "type")
        elif signal.topic is not None:
            topic = scope.external.get(signal.topic)
            if topic is None:
                report.error(signal, missing("external topic", signal.topic, "the system", scope.external), "topic")
            elif signal.type is not None and topic.type != signal.type:
                report.error(
                    signal, f"signal type {signal.type!r} differs from its topic's type {topic.type!r}", "type"
                )
    _check_expects(plan, system, report)
    for dependency in plan.dependencies:
        waiter = agent_state(dependency)
        wanted = signals.get(dependency.signal)
        if wanted is None:
            report.error(dependency, missing("signal", dependency.signal, where, signals), "signal")
        elif waiter is not None and not _waits_for(system, waiter.mission, dependency.state, wanted.name):
            report.error(
                dependency,
                f"state {dependency.state!r} never waits for {wanted.name!r}: use signal('{wanted.name}') in a"
                f' transition out of it, or give its behavior an Input with signal="{wanted.name}"',
                "state",
            )
        elif wanted.agent == dependency.agent:
            report.error(
                dependency,
                f"signal {wanted.name!r} comes from agent {wanted.agent!r} itself; a dependency ties two agents",
                "signal",
            )


def sim_bodies(system: System) -> list[str]:
    """The simulated robots of ``system``: the ``body`` Params of its ``sim`` HWChannels, in order."""
    found = (p.value for node in system.nodes for channel in node.channels if channel.backend == "sim"
             for p in channel.params if p.name == "body")  # fmt: skip
    return list(dict.fromkeys(found))


def _check_expects(plan: Plan, system: System, report: Reporter) -> None:
    """Each ``<Expect>`` (D300) names an environment Object or a simulated robot (D306), and the Object or
    Area it must end on or in."""
    environment = system.environment
    if environment is None:  # a Part with the plans alone: checked once the System includes the environment
        return
    objects = [o.name for o in environment.objects]
    areas = [a.name for a in environment.areas]
    robots = sim_bodies(system)
    for expect in plan.expects:
        if expect.object not in objects and expect.object not in robots:
            report.error(expect, missing("object", expect.object, "the environment or the simulated robots",
                                         [*objects, *robots]), "object")
        if expect.on is None and expect.in_ is None:
            report.error(expect, f'expect of {expect.object!r} says neither on="…" nor in="…"', "object")
        if expect.on is not None and expect.on not in objects:
            report.error(expect, missing("object", expect.on, "the environment", objects), "on")
        if expect.in_ is not None and expect.in_ not in areas:
            report.error(expect, missing("area", expect.in_, "the environment", areas), "in")


def _check_randomise(system: System, report: Reporter) -> None:
    """``<Validation><Randomise objects>`` (D301) names environment Objects, each once."""
    randomise = None if system.validation is None else system.validation.randomise
    if randomise is None or not randomise.objects or system.environment is None:
        return
    objects = [o.name for o in system.environment.objects]
    seen: set[str] = set()
    for name in randomise.objects:
        if name not in objects:
            report.error(randomise, missing("object", name, "the environment", objects), "objects")
        elif name in seen:
            report.error(randomise, f"object {name!r} is named twice in objects", "objects")
        seen.add(name)
