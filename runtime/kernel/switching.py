"""Controller switching (§3.1.2.7): bumpless hand-over of outputs, and the ``<Switch>`` criteria.

Each controller's ``<Switch to=… when=…>`` conditions (parsed once, with their records) are
evaluated at the start of its period while it is active; the first that holds hands the
controller's outputs over to ``to``. The conditions' functions are ``alarm(name)`` (an alarm
of the node's monitor is active), ``stale(topic)`` and ``value(topic)`` (the newest sample of a
topic the node watches), and the name ``elapsed`` (seconds since the controller became active).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

from ckmconf.expressions import Condition, Environment, evaluate
from ckmconf.model.kernel import Controller as ControllerRecord

from ..network.api import Subscription
from .monitor import MonitorService
from .services import ControlService, stale_after

Report = Callable[[str, dict[str, Any]], None]


class ControllerSwitching:
    """Switches between a node's controllers, on command, on an alarm or on a ``<Switch>`` criterion."""

    def __init__(
        self,
        controllers: Mapping[str, ControlService],
        watch: Callable[[str], Subscription],
        watched: Mapping[str, Subscription],
        report: Report,
        lock: threading.RLock,
    ) -> None:
        """``watch(topic)`` subscribes to a topic a condition reads; ``watched`` holds those subscriptions;
        ``lock`` is the node's, held while controllers change hands (and while the node adds or removes one)."""
        self._lock = lock
        self._controllers = controllers
        self._watch = watch
        self._watched = watched
        self._report = report
        self._criteria: dict[str, list[tuple[str, Condition]]] = {}
        self.monitor: MonitorService | None = None  # alarm() is false until the node's monitor is set

    def add_criteria(self, record: ControllerRecord) -> None:
        """Take the controller's ``<Switch>`` conditions and watch the topics they read."""
        self._criteria[record.name] = [(sw.to, sw.condition) for sw in record.switches]
        for switch in record.switches:
            for function, args in switch.condition.calls:
                if function in ("stale", "value"):
                    self._watch(str(args[0]))

    def forget(self, name: str) -> None:
        """Drop a removed controller's criteria."""
        self._criteria.pop(name, None)

    def tick(self, control: ControlService) -> Callable[[], None]:
        """The required part of the controller's period: its criteria first, then its control law."""

        def tick() -> None:
            if control.active:
                for target, condition in self._criteria.get(control.record.name, ()):
                    if evaluate(condition, self.environment(control)):
                        self.switch(target, reason=f"criterion of {control.record.name}")
                        return
            control.compute()

        return tick

    def environment(self, control: ControlService) -> Environment:
        """What a ``<Switch>`` condition of ``control`` is evaluated against, now."""

        def stale(topic: str) -> bool:
            subscription = self._watched.get(topic)
            history = subscription.history() if subscription is not None else []
            if subscription is None or not history:
                return True
            age = time.time() - (history[-1].stamp - history[-1].offset)
            return age > stale_after(subscription.qos, control.record.period)

        def value(topic: str) -> Any:
            subscription = self._watched.get(topic)
            history = subscription.history() if subscription is not None else []
            return history[-1].value if history else None

        monitor = self.monitor
        return Environment(
            functions={
                "alarm": lambda name: monitor is not None and monitor.active(name),
                "stale": stale,
                "value": value,
            },
            names={"elapsed": time.monotonic() - control.since},
        )

    def switch(self, to: str, reason: str = "command") -> None:
        """Hand the outputs of the active controller(s) sharing ``to``'s outputs over to ``to``, bumplessly."""
        with self._lock:
            target = self._controllers[to]
            outputs = {p.topic for p in target.record.outputs}
            previous = None
            for control in self._controllers.values():
                if control is not target and control.active and outputs & {p.topic for p in control.record.outputs}:
                    previous = control.last_output
                    control.deactivate()
            target.activate(previous)
        self._report("controller-switched", {"to": to, "reason": reason})
