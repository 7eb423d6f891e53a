"""The interface part of ``verify``: each service's interface, and each behavior's ``<Uses>`` against its kind.

:class:`InterfaceChecks` adds to :class:`~.checker.Checker` the two checks of
:mod:`.interfaces`: a ``<Service>`` is of the interface it declares (``interface=``) or that its
profiles' output plugin kind ``PROVIDES`` (the two must agree), and has that interface's ports; a
``<Behavior>``'s ``<Uses>`` bind every service its kind ``USES`` to a service of the declared
interface. Problems are reported at the element or attribute that holds them.
"""

from __future__ import annotations

from typing import Any

from ckmconf.model import Behavior, Plugin, Profile, Service, SmartResource
from ckmconf.model.missions import Uses

from .checker import Checker
from .interfaces import STANDARD, Use, provided_by, uses_of


def _a(noun: str) -> str:
    """``noun`` with its indefinite article ("an arm-motion", "a navigation")."""
    return f"{'an' if noun[:1] in 'aeiou' else 'a'} {noun}"


class InterfaceChecks(Checker):
    """Service interfaces (``self.interfaces``: ``RESOURCE.SERVICE`` → interface name or None)."""

    interfaces: dict[str, str | None]
    lacking: dict[str, str]
    """Services whose kind implements an interface whose ports they lack, and why (for a behavior using one)."""

    def _service_interface(
        self,
        resource: SmartResource,
        service: Service,
        used: list[Profile],
        kinds: dict[str, tuple[Plugin, type[Any] | None]],
    ) -> None:
        """Resolve and check one service's interface (its ``interface=`` and its output plugin kinds)."""
        ref = f"{resource.name}.{service.name}"
        declared = service.interface
        if declared is not None and declared not in STANDARD:
            self.report.error(service, f"service {ref!r}: no interface {declared!r} (known: {', '.join(STANDARD)})",
                              "interface")
            self.interfaces[ref] = None
            return
        provided: dict[str, str] = {}  # interface → the plugin (kind) that provides it
        for profile in used:
            plugin, cls = kinds.get(profile.output_plugin(), (None, None))
            name = provided_by(cls)
            if plugin is not None and name is not None:
                provided.setdefault(name, f"{plugin.name!r} ({plugin.kind})")
        if declared is not None and provided and set(provided) != {declared}:
            shown = ", ".join(f"{name} (plugin {who})" for name, who in provided.items())
            self.report.error(service, f"service {ref!r} declares interface {declared!r}, but its output plugins "
                                       f"implement {shown}", "interface")
            self.interfaces[ref] = None
            return
        elif declared is None and len(provided) > 1:
            shown = ", ".join(f"{name} (plugin {who})" for name, who in provided.items())
            self.report.error(service, f"service {ref!r}: its profiles' output plugins implement different "
                                       f"interfaces: {shown}; give the one it offers as interface=\"…\"")
        interface = declared or (next(iter(provided)) if len(provided) == 1 else None)
        self.interfaces[ref] = interface
        if interface is None:
            return
        lacking = STANDARD[interface].missing(
            {i.name for i in service.inputs}, {o.name for o in service.outputs}, {p.name for p in service.parameters},
            set(service.measure_names()),
        )
        if lacking and declared is None:  # its kind's interface, not claimed: only a behavior using it needs it
            self.interfaces[ref] = None
            self.lacking[ref] = f"{ref!r} would be {_a(interface)} service but has no {', '.join(lacking)}"
        elif lacking:
            self.report.error(service, f"service {ref!r} is {_a(interface)} service (docs/interfaces.md) but has no "
                                       f"{', '.join(lacking)}")

    def _behavior_uses(self, behavior: Behavior, cls: type[Any]) -> None:
        """Each service the behavior kind ``USES`` against the behavior's ``<Uses>`` elements."""
        declared = uses_of(cls)
        if declared is None:
            return
        owner = f"behavior {behavior.name!r} ({behavior.kind})"
        bound = {u.alias: u for u in behavior.uses}
        for use in declared:
            element = bound.get(use.alias)
            if element is None:
                self._unbound(behavior, owner, use, [u for u in behavior.uses if u.alias not in declared.by_alias()])
            elif element.service in self.interfaces:  # an unknown service: the loader reported it
                self._bound(element, owner, use, self.interfaces[element.service])

    def _unbound(self, behavior: Behavior, owner: str, use: Use, extra: list[Uses]) -> None:
        """A declared alias no ``<Uses>`` binds: a service of its interface under another alias is the
        likely slip; otherwise a required alias is missing."""
        slip = next((u for u in extra if self.interfaces.get(u.service) == use.interface), None)
        if slip is not None:
            self.report.error(slip, f"{owner} uses {slip.service!r} as {slip.alias!r}, but its kind reads "
                                    f"{_a(use.interface)} service as {use.alias!r}: write as=\"{use.alias}\"", "as")
        elif not use.optional:
            self.report.error(behavior, f"{owner} needs {_a(use.interface)} service as {use.alias!r} "
                                        f"({use.doc or 'docs/interfaces.md'}): add <Uses service=\"…\" "
                                        f"as=\"{use.alias}\"/>")

    def _bound(self, element: Uses, owner: str, use: Use, actual: str | None) -> None:
        """A declared alias bound to a service: it must be of the declared interface."""
        if actual == use.interface:
            return
        if actual is not None:
            what = f"not {_a(actual)} one"
        elif element.service in self.lacking:
            what = self.lacking[element.service]
        else:
            what = f"{element.service!r} declares no interface (give its <Service> interface=\"{use.interface}\")"
        self.report.error(element, f"{owner} uses {element.service!r} as {use.alias!r}, which must be "
                                   f"{_a(use.interface)} service{'; ' if actual is None else ', '}{what}", "service")
