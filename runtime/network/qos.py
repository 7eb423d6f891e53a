"""QoS and event plumbing shared by every transport: event emission, deadlines and lifespan (``<Topic>``, §3.1.2.10).

The transports differ in how samples travel; what a subscriber sees once a sample arrives —
events on callbacks and on ``EVENTS_TOPIC``, one missed-deadline event per silent period,
stale samples dropped — must not, so it lives here once.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable

from .api import EVENTS_TOPIC, NetworkEvent, Sample, Subscription

LOG = logging.getLogger("ckm.network")

# The watchdog wakes at the next due deadline, but never sleeps longer than this: a
# subscription made while it sleeps is first checked at most this late.
MAX_WATCH_SLEEP = 0.05
MIN_WATCH_SLEEP = 0.002


def emit_event(
    event: NetworkEvent,
    callbacks: Iterable[Callable[[NetworkEvent], None]],
    subscribers: Iterable[Subscription],
    guid: int,
) -> None:
    """Hand ``event`` to every callback, then to the local ``EVENTS_TOPIC`` subscribers.

    A failing callback is logged and skipped so one bad listener cannot silence the others.
    """
    for callback in list(callbacks):
        try:
            callback(event)
        except Exception:
            LOG.exception("event callback failed")
    local = list(subscribers)
    if local:
        now = time.time()
        sample = Sample(EVENTS_TOPIC, event, now, guid, 0, now)
        for subscription in local:
            subscription.deliver(sample)


def fresh_subscribers(subscribers: list[Subscription], sample: Sample) -> list[Subscription]:
    """The subscribers for which ``sample`` is still within the topic's lifespan."""
    return [s for s in subscribers if s.qos.lifespan is None or sample.age <= s.qos.lifespan]


def deliver(subscribers: list[Subscription], sample: Sample, emit: Callable[[NetworkEvent], None]) -> bool:
    """Hand a sample to the subscribers it is still fresh for; True (and one event) if it was stale for some."""
    fresh = fresh_subscribers(subscribers, sample)
    for subscription in fresh:
        subscription.deliver(sample)
    if len(fresh) < len(subscribers):
        emit(stale_event(sample))
        return True
    return False


def stale_event(sample: Sample) -> NetworkEvent:
    """The ``stale-dropped`` event for a sample older than its topic's lifespan."""
    return NetworkEvent("stale-dropped", sample.source, sample.topic, f"sample {sample.seq} is {sample.age:.3f} s old")


class DeadlineWatchdog:
    """Emits ``deadline-missed`` once per ``<Topic deadline>`` period in which a subscription got no sample."""

    def __init__(
        self, watched: Callable[[], list[Subscription]], emit: Callable[[NetworkEvent], None], name: str
    ) -> None:
        self._watched = watched
        self._emit = emit
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        """Start the watchdog thread."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the watchdog thread and wait for it (not from itself)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2)

    def _run(self) -> None:
        sleep = MAX_WATCH_SLEEP
        while not self._stop.wait(sleep):
            now = time.monotonic()
            sleep = MAX_WATCH_SLEEP
            for subscription in self._watched():
                deadline = subscription.qos.deadline
                if deadline is None:
                    continue
                if now - subscription.last_arrival > deadline:
                    subscription.last_arrival = now  # re-armed: one event per missed period
                    self._emit(
                        NetworkEvent("deadline-missed", None, subscription.qos.name, f"no sample for {deadline:g} s")
                    )
                due = subscription.last_arrival + deadline - now
                sleep = max(MIN_WATCH_SLEEP, min(sleep, due))


class SubscriptionTable:
    """What both transports keep of their local subscribers, and the two queries they share.

    The owner sets ``_subs`` (topic → subscriptions), ``_lock``, ``_callbacks`` and ``guid``.
    """

    _subs: dict[str, list[Subscription]]
    _lock: threading.RLock
    _callbacks: list[Callable[[NetworkEvent], None]]
    guid: int

    def _emit(self, event: NetworkEvent) -> None:
        with self._lock:
            local = list(self._subs.get(EVENTS_TOPIC, ()))
        emit_event(event, self._callbacks, local, self.guid)

    def subscribed(self, topic: str) -> bool:
        """Transport.subscribed: True unless the transport can tell (CKMultiPeer does, D245)."""
        return True

    def _watched(self) -> list[Subscription]:
        """The subscriptions whose deadline runs: a passive one only while someone asks for its topic (D245)."""
        now = time.monotonic()
        watched = []
        with self._lock:
            for name, subs in self._subs.items():
                for subscription in subs:
                    if subscription.qos.deadline is None:
                        continue
                    if subscription.passive and not self.subscribed(name):
                        subscription.last_arrival = now  # re-armed: its deadline runs from the next ask
                        continue
                    watched.append(subscription)
        return watched
