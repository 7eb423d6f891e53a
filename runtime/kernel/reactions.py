"""Alarm reactions (§3.1.2.6–7): what a node does when an ``<Alarm action=…>`` of its monitor fires.

``safe-stop`` drives every actuator to its safe value; ``switch`` hands the outputs over to the
alarm's target controller; ``delegate`` gives the target controller to an idle service node (on
its own thread: handing over waits for the taker); ``restart`` restarts the alarm's partition.
A reaction the node cannot carry out (no delegation, no partition supervisor, an unknown target)
is reported as a ``reaction-unavailable`` event rather than ignored.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Any, Protocol

from ckmconf.model import Alarm

from .delegation import Delegation
from .services import ActuationService, ControlService


class Restarts(Protocol):
    """What restarting a partition needs: the supervisor of the node's partition processes."""

    def on_alarm(self, alarm: Alarm) -> None:
        """Restart the alarm's partition (§3.1.2.6)."""
        ...


class ReactionHost(Protocol):
    """What the reactions need of their node (the kernel's ``NodeRuntime`` is one)."""

    @property
    def actuators(self) -> Mapping[str, ActuationService]:
        """The node's actuation services by actuator name."""
        ...

    @property
    def controllers(self) -> Mapping[str, ControlService]:
        """The node's control services by controller name."""
        ...

    @property
    def delegation(self) -> Delegation | None:
        """The node's code delegation, if it has one."""
        ...

    @property
    def partitions(self) -> Restarts | None:
        """The node's partition supervisor, if it has partitions."""
        ...

    def switch(self, to: str, reason: str = "command") -> None:
        """Hand the outputs over to controller ``to``."""
        ...

    def idle_node(self) -> str | None:
        """Where delegated work goes."""
        ...

    def report(self, kind: str, detail: dict[str, Any]) -> None:
        """Record a node event."""
        ...


def react(host: ReactionHost, alarm: Alarm) -> None:
    """Carry out the alarm's action on ``host`` (the monitor calls it when the alarm is raised)."""
    if alarm.action == "safe-stop":
        for actuation in host.actuators.values():
            actuation.safe_stop()
    elif alarm.action == "switch" and alarm.target is not None:
        host.switch(alarm.target, reason=f"alarm {alarm.name}")
    elif alarm.action == "delegate" and alarm.target in host.controllers and host.delegation is not None:
        taker = host.idle_node()
        if taker is not None:  # handing over waits for the taker: not on the monitor's thread
            threading.Thread(target=host.delegation.give, args=(alarm.target, taker), daemon=True).start()
    elif alarm.action == "restart" and host.partitions is not None:
        host.partitions.on_alarm(alarm)
    else:
        host.report("reaction-unavailable", {"alarm": alarm.name, "action": alarm.action})
