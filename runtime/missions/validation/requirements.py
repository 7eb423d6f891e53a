"""Static checks of what a mission's behaviors ask of the Smart Resources (§5.1.1, eq. 5.5).

A behavior's ``<Uses>`` must name a service some SmartResource provides, and each ``<Require>``
(a quality requirement QR) must be meetable by one of that service's scenarios. "Meetable"
follows the TCM's own rule (docs/decisions.md D37): a scenario is compatible with a requirement
when each of its policies on the required measure lies within the requirement's bounds (a
scenario with no policy on the measure does not constrain it). A requirement with no compatible
scenario — or a set of requirements on one service no single scenario is compatible with — can
never be met while the TCM keeps the policies: an error. A requirement on a measure no scenario
bounds is *unproven* (the model says nothing about it); with ``strict`` it is a warning.
"""

from __future__ import annotations

from ckmconf.model import Behavior, Service, System, Transition
from ckmconf.model.missions import Require, Uses
from ckmconf.model.resources import Policy, Scenario

from .findings import Finding, arrow, finding


def _bounds(lower: float | None, upper: float | None) -> str:
    return f"[{'-inf' if lower is None else f'{lower:g}'}, {'inf' if upper is None else f'{upper:g}'}]"


def _within(policy: Policy, require: Require) -> bool:
    """The TCM's compatibility test (runtime.resources.tcm_rating.within): the policy lies inside the QR."""
    low = require.lower is None or (policy.lower is not None and policy.lower >= require.lower)
    high = require.upper is None or (policy.upper is not None and policy.upper <= require.upper)
    return low and high


def compatible(scenario: Scenario, requires: tuple[Require, ...] | list[Require]) -> bool:
    """Whether the scenario's policies keep every one of the requirements' measures in bounds."""
    return all(_within(p, r) for r in requires for p in scenario.policies if p.measure == r.measure)


def check_behavior(
    system: System, behavior: Behavior, *, mission: str, state: str, strict: bool = False
) -> list[Finding]:
    """Services, requirements and signal inputs of one behavior (reported once per behavior)."""
    found: list[Finding] = []
    where = f"behavior {behavior.name!r} (state {state!r} of mission {mission!r})"
    for uses in behavior.uses:
        provided = system.service(uses.service)
        if provided is None:
            found.append(_not_provided(system, uses, where, mission, state))
            continue
        found.extend(_check_requires(uses, provided[1], where, mission, state, strict))
    signals = {s.name for plan in system.plans for s in plan.signals}
    for port in behavior.inputs:
        if port.signal is not None and system.plans and port.signal not in signals:
            message = (
                f"{where} waits for signal {port.signal!r}, which no plan emits"
                f" (plan signals: {', '.join(sorted(signals)) or 'none'}); declare it with <Signal> in a plan"
            )
            found.append(finding("unknown-signal", "error", message, port, mission=mission, state=state))
    return found


def _not_provided(system: System, uses: Uses, where: str, mission: str, state: str) -> Finding:
    resource = system.resource(uses.resource)
    if resource is None:
        known = ", ".join(sorted(r.name for r in system.resources)) or "none"
        detail = f"there is no SmartResource {uses.resource!r} (resources: {known})"
    else:
        known = ", ".join(s.name for s in resource.services) or "none"
        detail = f"SmartResource {resource.name!r} has no service {uses.service_name!r} (its services: {known})"
    message = f"{where} uses service {uses.service}, which nothing provides: {detail}; fix the name or add the service"
    return finding("service-not-provided", "error", message, uses, mission=mission, state=state)


def _check_requires(uses: Uses, service: Service, where: str, mission: str, state: str, strict: bool) -> list[Finding]:
    found: list[Finding] = []
    measures = service.measure_names()
    usable: list[Require] = []
    for require in uses.requires:
        qr = f"{where} requires {uses.service} {require.measure} in {_bounds(require.lower, require.upper)}"
        if require.measure not in measures:
            message = f"{qr}, but the service has no such quality measure (it has: {', '.join(measures) or 'none'})"
            found.append(finding("unmeetable-requirement", "error", message, require, mission=mission, state=state))
            continue
        if require.lower is not None and require.upper is not None and require.lower > require.upper:
            message = f"{qr}: the bounds are empty; swap them"
            found.append(finding("unmeetable-requirement", "error", message, require, mission=mission, state=state))
            continue
        bounded = [s for s in service.scenarios if any(p.measure == require.measure for p in s.policies)]
        if service.scenarios and not any(compatible(s, [require]) for s in service.scenarios):
            allowed = "; ".join(
                f"{s.name} allows {_bounds(p.lower, p.upper)}"
                for s in bounded
                for p in s.policies
                if p.measure == require.measure
            )
            message = (
                f"{qr}, but no scenario keeps it there ({allowed}); widen the requirement or add a scenario"
                " whose policy on it lies within these bounds"
            )
            found.append(finding("unmeetable-requirement", "error", message, require, mission=mission, state=state))
            continue
        usable.append(require)
        if strict and not bounded:
            message = (
                f"{qr}, but no scenario of the service has a policy on {require.measure}: the model cannot show"
                " it holds; add a Scenario with a Policy on it to characterise the service"
            )
            found.append(finding("unproven-requirement", "warning", message, require, mission=mission, state=state))
    if len(usable) > 1 and service.scenarios and not any(compatible(s, usable) for s in service.scenarios):
        measures_text = ", ".join(r.measure for r in usable)
        message = (
            f"{where}: no single scenario of {uses.service} meets all of its requirements ({measures_text}) at once;"
            " relax one of them"
        )
        found.append(finding("unmeetable-requirement", "error", message, uses, mission=mission, state=state))
    return found


def check_fields(
    system: System,
    behavior: Behavior | None,
    attributes: list[tuple[str, str]],
    transition: Transition,
    *,
    mission: str,
) -> list[Finding]:
    """``alias.field`` in a condition: a service the state's behavior uses, and one of its outputs or measures."""
    found: list[Finding] = []
    uses = {u.alias: u for u in behavior.uses} if behavior is not None else {}
    label = arrow(transition.from_, transition.to)
    for alias, field in dict.fromkeys(attributes):
        chosen = uses.get(alias)
        if chosen is None:
            owner = f"behavior {behavior.name!r}" if behavior is not None else f"state {transition.from_!r}"
            message = (
                f"transition {label} reads {alias}.{field}, but {owner} uses no service as {alias!r}"
                f" (aliases: {', '.join(uses) or 'none'})"
            )
            found.append(
                finding(
                    "unknown-alias",
                    "error",
                    message,
                    transition,
                    mission=mission,
                    state=transition.from_,
                    transition=label,
                )
            )
            continue
        provided = system.service(chosen.service)
        if provided is None:
            continue  # reported as service-not-provided
        fields = [p.name for p in provided[1].outputs] + [m.name for m in provided[1].measures]
        if field not in fields:
            message = (
                f"transition {label} reads {alias}.{field}, but service {chosen.service} has no output or measure"
                f" {field!r} (it has: {', '.join(fields) or 'none'})"
            )
            found.append(
                finding(
                    "unknown-field",
                    "error",
                    message,
                    transition,
                    mission=mission,
                    state=transition.from_,
                    transition=label,
                )
            )
    return found
