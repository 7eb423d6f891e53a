"""Monitoring and alarms (§3.1.2.4): measures sampled each monitor period, thresholds, reactions.

An alarm is raised when its measure goes above ``above`` or below ``below`` and stays there for
``hold`` seconds; it clears when the measure is back within bounds. Raising and clearing are
events on the node's alarm topic and in the log; a raised alarm may trigger the kernel's
reaction (safe stop, controller switch, delegation, partition restart).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import psutil

from ckmconf.model import Alarm, Monitor

from ..network.api import Subscription
from .scheduler import Scheduler


@dataclass
class AlarmState:
    """The run-time state of one kernel.xsd ``Alarm``: active or not, since when, last value, raise count."""

    record: Alarm
    active: bool = False
    since: float | None = None  # when the condition started to hold
    value: float = 0.0
    raised: int = 0


class MonitorService:
    """Samples the node's measures and raises, clears and acts on its alarms."""

    def __init__(
        self,
        monitor: Monitor,
        *,
        node: str,
        scheduler: Scheduler,
        subscriptions: dict[str, Subscription],
        crashes: Callable[[str], int],
        report: Callable[[str, dict[str, Any]], None],
        react: Callable[[Alarm], None],
        asked: Callable[[str], bool] = lambda topic: True,
    ) -> None:
        self.monitor = monitor
        self.node = node
        self.scheduler = scheduler
        self.subscriptions = subscriptions
        self.crashes = crashes
        self.report = report
        self.react = react
        self.asked = asked  # does a subscriber ask for a topic the monitor only observes (D245)
        self._asked_since: dict[str, float] = {}
        self._watched_since: dict[str, float] = {}
        self.alarms = {a.name: AlarmState(a) for a in monitor.alarms}
        self._misses: dict[str, int] = {}
        self._crashes: dict[str, int] = {}
        psutil.cpu_percent(None)  # the first reading only starts the measurement

    def _staleness(self, topic: str) -> float:
        """Seconds since the topic's newest sample; a topic never seen is as old as the watch, so its
        producers have the alarm's own limit to start (D311). A topic of a lazy producer, which the
        monitor only observes, is stale only while a subscriber asks for it, counted from the ask (D245)."""
        subscription = self.subscriptions.get(topic)
        sample = subscription.history()[-1] if subscription is not None and subscription.history() else None
        now = time.time()
        watched = self._watched_since.setdefault(topic, now)
        age = now - watched if sample is None else now - (sample.stamp - sample.offset)
        if subscription is None or not subscription.passive:
            return age
        if not self.asked(topic):
            self._asked_since.pop(topic, None)
            return 0.0
        return min(age, now - self._asked_since.setdefault(topic, now))

    def active(self, name: str) -> bool:
        """Whether alarm ``name`` is raised now (False for an unknown name)."""
        state = self.alarms.get(name)
        return state is not None and state.active

    def measure(self, alarm: Alarm) -> float:
        """Sample the alarm's measure (kernel.xsd ``Alarm/@measure``, §3.1.2.4).

        Returns:
            A fraction for cpu and memory, seconds of staleness, the count of new deadline misses or
            partition crashes since the last sample, or the largest recent jitter or execution time.
        """
        kind = alarm.measure
        if kind == "cpu":
            return float(psutil.cpu_percent(None)) / 100
        if kind == "memory":
            return float(psutil.virtual_memory().percent) / 100
        if kind == "staleness":
            return self._staleness(alarm.topic or "")
        if kind == "partition-crash":
            total = self.crashes(alarm.partition or "")
            new = total - self._crashes.get(alarm.name, 0)
            self._crashes[alarm.name] = total
            return float(new)
        task = self.scheduler.tasks.get(f"{self.node}.{alarm.task}")
        if task is None:
            return 0.0
        if kind == "deadline-misses":
            new = task.stats.misses - self._misses.get(alarm.name, 0)
            self._misses[alarm.name] = task.stats.misses
            return float(new)
        recent = (task.stats.jitter if kind == "jitter" else task.stats.exec_time).recent(200)
        return max((abs(v) for v in recent), default=0.0)

    def tick(self) -> None:
        """Sample every alarm, raise or clear it, report the change and trigger its reaction (§3.1.2.4)."""
        now = time.monotonic()
        for state in self.alarms.values():
            alarm = state.record
            value = self.measure(alarm)
            state.value = value
            if alarm.measure == "partition-crash":
                breached = value > 0
            else:
                breached = (alarm.above is not None and value > alarm.above) or (
                    alarm.below is not None and value < alarm.below
                )
            if not breached:
                state.since = None
                if state.active:
                    state.active = False
                    self.report("alarm-cleared", {"alarm": alarm.name, "value": value})
                continue
            state.since = now if state.since is None else state.since
            if not state.active and now - state.since >= alarm.hold:
                state.active = True
                state.raised += 1
                self.report(
                    "alarm",
                    {
                        "alarm": alarm.name,
                        "measure": alarm.measure,
                        "value": value,
                        "severity": alarm.severity,
                        "action": alarm.action,
                    },
                )
                if alarm.action != "none":
                    self.react(alarm)
