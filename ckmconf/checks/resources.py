"""Semantic checks of Smart Resources (resources.xsd, ch. 4): plugins, profiles, services, quality, scenarios, TCM."""

from __future__ import annotations

from ..binding import Record
from ..model import Parameter, Profile, Service, SmartResource, System
from .report import Reporter, missing
from .scope import Scope


def check_resources(system: System, scope: Scope, report: Reporter) -> None:
    """Check every ``<SmartResource>`` (resources.xsd, ch. 4): node, plugins, profiles, services, TCM."""
    report.unique(system.resources, "SmartResource", "the system")
    nodes = [n.name for n in system.nodes]
    for resource in system.resources:
        node = system.node(resource.node)
        if node is None:
            report.error(resource, missing("node", resource.node, "the system", nodes), "node")
        where = f"SmartResource {resource.name!r}"
        report.unique(resource.plugins, "plugin", where)
        report.unique(resource.profiles, "profile", where)
        report.unique(resource.services, "service", where)
        plugins = [p.name for p in resource.plugins]
        for profile in resource.profiles:
            _check_profile(profile, plugins, where, report)
        for service in resource.services:
            _check_service(resource, service, scope, report)


def _check_profile(profile: Profile, plugins: list[str], where: str, report: Reporter) -> None:
    used = profile.root.plugins()
    seen: set[str] = set()
    stack = [profile.root]
    while stack:
        use = stack.pop()
        if use.plugin not in plugins:
            report.error(use, missing("plugin", use.plugin, where, plugins), "plugin")
        elif use.plugin in seen:
            report.error(use, f"plugin {use.plugin!r} appears twice in profile {profile.name!r}", "plugin")
        seen.add(use.plugin)
        stack.extend(use.uses)
    if profile.output is not None:
        if profile.output not in used:
            report.error(profile, missing("plugin", profile.output, f"profile {profile.name!r}", used), "output")
    elif len(profile.root.leaves()) > 1:
        leaves = ", ".join(profile.root.leaves())
        report.error(profile, f'profile {profile.name!r} has several leaves ({leaves}); name its output (output="…")')


def _check_service(resource: SmartResource, service: Service, scope: Scope, report: Reporter) -> None:
    where = f"service {resource.name}.{service.name}"
    node = scope.system.node(resource.node)
    for port in (*service.inputs, *service.outputs) if node is not None else ():  # no node: reported once
        if scope.topic(node, port.topic) is None:
            report.error(
                port, missing("topic", port.topic, f"node {resource.node!r}", scope.visible_topics(node)), "topic"
            )
    report.unique(service.inputs, "input", where)
    report.unique(service.outputs, "output", where)
    report.unique(service.parameters, "parameter", where)
    report.unique(service.measures, "quality measure", where)
    report.unique(service.scenarios, "scenario", where)
    for parameter in service.parameters:
        _check_parameter(parameter, report)
    measures = [m.name for m in service.measures]
    if service.performance is not None and service.performance not in measures:
        report.error(service, missing("quality measure", service.performance, where, measures), "performance")
    _check_combined(service, measures, where, report)
    measures = service.measure_names()
    profiles = [p.name for p in resource.profiles]
    for scenario in service.scenarios:
        if scenario.profile not in profiles:
            report.error(
                scenario, missing("profile", scenario.profile, f"SmartResource {resource.name!r}", profiles), "profile"
            )
        report.unique(scenario.policies, "policy for measure", f"scenario {scenario.name!r}", key="measure")
        for policy in scenario.policies:
            if policy.measure not in measures:
                report.error(policy, missing("quality measure", policy.measure, where, measures), "measure")
            check_bounds(policy, policy.lower, policy.upper, report)
    if service.tcm is not None:
        names = [s.name for s in service.scenarios]
        if not service.scenarios:
            report.error(service.tcm, f"{where} has a TCM but no Scenario to choose from")
        elif service.tcm.initial is not None and service.tcm.initial not in names:
            report.error(service.tcm, missing("scenario", service.tcm.initial, where, names), "initial")


def _check_combined(service: Service, measures: list[str], where: str, report: Reporter) -> None:
    """CombinedMeasure (eq. 4.5): a new name, summing two or more distinct QualityMeasures."""
    for combined in service.combined:
        if combined.name in measures:
            report.error(combined, f"{where} already has a quality measure {combined.name!r}", "name")
        if len(combined.measures) < 2:
            report.error(combined, "a combined measure sums at least two quality measures (eq. 4.5)", "measures")
        seen: set[str] = set()
        for name in combined.measures:
            if name in seen:
                report.error(
                    combined, f"measure {name!r} is summed twice (eq. 4.5 needs independent measures)", "measures"
                )
            elif name in measures:
                pass
            elif name in service.combinations():
                report.error(combined, f"{name!r} is a combined measure: sum its quality measures instead", "measures")
            else:
                report.error(combined, missing("quality measure", name, where, measures), "measures")
            seen.add(name)
    report.unique(service.combined, "combined measure", where)


def check_bounds(record: Record, lower: float | None, upper: float | None, report: Reporter) -> None:
    """Quality bounds: at least one, and lower ≤ upper."""
    if lower is None and upper is None:
        report.error(record, "give a lower bound, an upper bound or both")
    elif lower is not None and upper is not None and lower > upper:
        report.error(record, f"lower bound {lower:g} is above upper bound {upper:g}", "lower")


def check_value(parameter: Parameter, value: str) -> str | None:
    """Why a text is not a valid value of a parameter, or None when it is."""
    text = value.strip()
    if parameter.type == "bool":
        return None if text in ("true", "false", "1", "0") else "must be true or false"
    if parameter.type == "enum":
        allowed = parameter.values or ()
        return None if text in allowed else f"must be one of {', '.join(allowed)}"
    if parameter.type in ("int", "float"):
        try:
            number = int(text) if parameter.type == "int" else float(text)
        except ValueError:
            return "must be a whole number" if parameter.type == "int" else "must be a number"
        if number != number or number in (float("inf"), float("-inf")):
            return "must be a finite number"
        if parameter.min is not None and number < parameter.min:
            return f"must be at least {parameter.min:g}"
        if parameter.max is not None and number > parameter.max:
            return f"must be at most {parameter.max:g}"
    return None


def _check_parameter(parameter: Parameter, report: Reporter) -> None:
    if parameter.type == "enum" and not parameter.values:
        report.error(parameter, 'an enum parameter needs its values (values="A B C")', "type")
        return
    if parameter.values and parameter.type != "enum":
        report.error(parameter, "values are only for enum parameters", "values")
    if parameter.min is not None and parameter.max is not None and parameter.min > parameter.max:
        report.error(parameter, f"min ({parameter.min:g}) is above max ({parameter.max:g})", "min")
    if parameter.default is not None:
        problem = check_value(parameter, parameter.default)
        if problem:
            report.error(parameter, f"default {parameter.default!r} {problem}", "default")
