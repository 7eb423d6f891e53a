"""Smart Resources hosted by a node on the CKM kernel (§3.1.1, §4.2): built, started, stopped, measured.

A node hosts the ``<SmartResource node=…>`` records that name it. What this runtime cannot run is
refused at its element rather than skipped (issue G): a resource on a ROS kernel (none runs here)
and a service without scenarios (services run only through their scenarios' SPT processing).
The statistics come from each resource's own ``statistics()``; the host keeps the last figures
taken at stop, so a finished run still reports them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ckmconf.errors import ConfigError
from ckmconf.model import Node, System

from ..network.api import Transport
from ..registry import Registry
from ..resources.resource import SmartResourceRuntime


class ResourceHost:
    """The Smart Resources one node runs (``resources``: name → runtime), in its main process."""

    def __init__(
        self,
        node: Node,
        system: System,
        transport: Transport,
        registry: Registry,
        wire_name: Callable[[str], str] | None = None,
    ) -> None:
        self.node, self.system, self.transport, self.registry = node, system, transport, registry
        self.wire_name = wire_name  # the name a topic travels under from this node (internal: node-local)
        self.resources: dict[str, SmartResourceRuntime] = {}
        self._final: dict[str, Any] | None = None

    def setup(self) -> None:
        """Build and set up each resource of this node; a problem is a ConfigError at its element."""
        for resource in self.system.resources:
            if resource.node != self.node.name:
                continue
            if resource.kernel != "ckm":
                raise ConfigError.of(
                    resource,
                    f"Smart Resource {resource.name!r} runs on a {resource.kernel!r} kernel, "
                    "which this runtime does not provide: it cannot run on node "
                    f"{self.node.name!r}",
                )
            for service in resource.services:
                if not service.scenarios:
                    raise ConfigError.of(
                        service,
                        f"service '{resource.name}.{service.name}' has no Scenario: the runtime runs "
                        "services only through their scenarios' SPT processing",
                    )
            runtime = SmartResourceRuntime(
                resource, self.transport, node=self.node.name, registry=self.registry, wire_name=self.wire_name
            )
            try:
                runtime.setup()  # a stream its records cannot make is a ConfigError already
            except (OSError, ValueError) as exc:  # a model file, a plugin's own check in its set-up
                raise ConfigError.of(resource, f"Smart Resource {resource.name!r}: {exc}") from None
            self.resources[resource.name] = runtime

    def start(self) -> None:
        """Start every hosted resource."""
        for resource in self.resources.values():
            resource.start()

    def keep_statistics(self) -> None:
        """Take the figures now (at stop, before the resources stop) and report those from then on."""
        self._final = self.statistics()

    def statistics(self) -> dict[str, Any]:
        """Each resource's ``statistics()`` by name (as they were at stop, once stopped)."""
        if self._final is not None:
            return self._final
        return {name: runtime.statistics() for name, runtime in self.resources.items()}
