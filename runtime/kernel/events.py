"""A node's event log: every event of the kernel (switches, alarms, delegation, partitions).

Each event is a dict ``{"node", "kind", "time", …detail}``. It is kept in memory (the recent
ones, bounded), handed to every sink (``ckm-run`` writes them to the run directory's
``events.jsonl``), logged, and published on the node's alarm topic (``Node.alarm_topic()``,
where the editor's live view and other nodes see it, §3.1.5.3).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

from ..network.api import Publisher

LOG = logging.getLogger("ckm.node")
EVENTS_KEPT = 10000  # recent events kept in memory; every event also goes to the event sinks
EventSink = Callable[[dict[str, Any]], None]
SERIOUS = ("error", "critical")
"""Alarm severities that mean the run broke: ckm-run's verdict fails on them (D147)."""


class EventLog:
    """The events of one node: kept (bounded), handed to the sinks, logged and published."""

    def __init__(self, node: str, publisher: Publisher) -> None:
        self.node = node
        self.events: list[dict[str, Any]] = []  # the recent ones (bounded); all go to the sinks
        self.sinks: list[EventSink] = []  # e.g. the run directory's events file
        self._publisher = publisher
        self.serious: dict[str, Any] | None = None  # the first error or critical alarm raised (never evicted)
        self.serious_count = 0

    def report(self, kind: str, detail: dict[str, Any]) -> None:
        """Record one event; a failing sink is logged and does not stop the others."""
        event = {"node": self.node, "kind": kind, "time": time.time(), **detail}
        self.events.append(event)
        if kind == "alarm" and event.get("severity") in SERIOUS:
            self.serious = self.serious or event
            self.serious_count += 1
        if len(self.events) > EVENTS_KEPT:
            del self.events[: EVENTS_KEPT // 2]
        for sink in self.sinks:
            try:
                sink(event)
            except Exception:
                LOG.exception("%s: an event sink failed", self.node)
        level = logging.INFO if kind == "controller-switched" else logging.WARNING
        LOG.log(level, "%s: %s %s", self.node, kind, detail)
        self._publisher.publish(event)
