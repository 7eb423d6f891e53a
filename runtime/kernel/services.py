"""The kernel's services for one node: sensory perception, control and actuation (§3.1.2.1–3).

Each runs as a scheduler task (actuation also reacts to every command as it arrives). They talk
through topics, so a controller may read a sensor of another node; when both sit in one node
the control service also hands its predicted future actions straight to the actuation service,
which plays them if commands stop, then the actuator's fallback actions, then its safe value.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ckmconf.model import Actuator, Sensor
from ckmconf.model.kernel import Controller as ControllerRecord

from ..network.api import Publisher, Subscription, TopicQoS
from ..resources import codec
from .extrapolate import extrapolate
from .interfaces import Backend, Controller, Value
from .vectors import Shaper

LOG = logging.getLogger("ckm.kernel")
Chain = Callable[[float, float], float]


class SensorService:
    """Samples a channel, adapts the raw value, publishes it timestamped, keeps recent samples.

    A scalar sensor publishes the adapted number. A vector sensor (``shape`` given, decision D99)
    publishes the whole read shaped for its topic (:mod:`runtime.kernel.vectors`); its ``chains``,
    one per element, adapt each element with its own state (``verify`` refuses chains on frames).
    """

    def __init__(
        self,
        record: Sensor,
        backend: Backend,
        chain: Chain,
        publisher: Publisher,
        *,
        shape: Shaper | None = None,
        chains: Sequence[Chain] | None = None,
        asked: Callable[[], bool] | None = None,
    ) -> None:
        self.record = record
        self.backend = backend
        self.chain = chain
        self.publisher = publisher
        self.shape = shape
        self.chains = list(chains or [])
        self.samples: deque[tuple[float, Any]] = deque(maxlen=8)  # (wall time, engineering value)
        self.asked = asked  # a lazy sensor's question: does a subscriber ask for the topic (D245)
        self.rested = 0  # periods a lazy sensor did not read
        self._orders: queue.Queue[tuple[Any, float, float, float] | None] | None = None  # reads in flight (D246)
        self.failure: Exception | None = None  # a collect's error, raised by the next tick
        self._failure_lock = threading.Lock()  # the collector sets it while a tick takes it
        self._stopped = threading.Event()

    def tick(self) -> None:
        """Read the channel, adapt and publish the value (sensory perception service, §3.1.2.1).

        A lazy sensor (``<Sensor lazy>``) reads nothing while no subscriber asks for its topic (D245).
        A backend with a ``latency`` (a simulated camera, D246) is asked now; its value is taken,
        adapted and published ``latency`` later by the sensor's collector thread, stamped now.
        """
        if self.asked is not None and not self.asked():
            self.rested += 1
            return
        if self.backend.latency <= 0:
            self._publish(self.backend.read(), None)
            return
        with self._failure_lock:
            failure, self.failure = self.failure, None
        if failure is not None:  # a collect that failed fails this task, where the scheduler sees it
            raise failure
        token, stamp = self.backend.request(), time.time()
        if self._orders is None:
            self._orders = queue.Queue()
            threading.Thread(target=self._collect, name=f"{self.record.name}-collect", daemon=True).start()
        self._orders.put((token, stamp, time.monotonic(), time.monotonic() + self.backend.latency))

    def _collect(self) -> None:
        assert self._orders is not None
        while (order := self._orders.get()) is not None:
            token, stamp, then, due = order
            delay = due - time.monotonic()
            if delay > 0 and not self._stopped.is_set():
                time.sleep(delay)  # on the run's clock: in lock-step the world runs on meanwhile
            if self._stopped.is_set():
                continue  # stopping: the read is dropped, not collected from a backend being closed
            try:
                self._publish(self.backend.collect(token), stamp, then)
            except Exception as exc:
                with self._failure_lock:
                    self.failure = exc

    def stop(self) -> None:
        """End the collector thread (a backend with a latency); reads still in flight are dropped.

        Not joined: it may sleep on a lock-step clock that this thread's waiting would hold.
        """
        self._stopped.set()
        if self._orders is not None:
            self._orders.put(None)

    def _publish(self, raw: Value, stamp: float | None, now: float | None = None) -> None:
        """Adapt, shape and publish one read, stamped ``stamp`` (None: now)."""
        if self.shape is None:
            now = time.monotonic() if now is None else now
            value: Any = self.chain(float(raw[0] if isinstance(raw, tuple | np.ndarray) else raw), now)
        elif self.chains:
            now = time.monotonic() if now is None else now
            elements = raw if isinstance(raw, tuple | np.ndarray) else (raw,)
            value = [chain(float(x), now) for chain, x in zip(self.chains, elements, strict=True)]
        else:
            value = raw
        stamp = time.time() if stamp is None else stamp
        if self.shape is not None:
            value = self.shape(value, stamp)
        self.samples.append((stamp, value))
        # a vector's arrays travel in the codec's plain form, as service outputs do: another
        # process (a partition, another node) decodes the same arrays a local subscriber gets
        self.publisher.publish(value if self.shape is None else codec.encode(value), stamp=stamp)


def stale_after(qos: TopicQoS, period: float) -> float:
    """The age after which a topic's newest sample is lost: the topic's lifespan, else three periods.

    One rule for a controller's inputs (``ControlService.read_inputs``) and for ``stale(topic)`` in
    a ``<Switch>`` condition (§3.1.2.7), ``period`` being the controller's (decision D141).
    """
    return qos.lifespan or 3 * period


@dataclass
class FutureActions:
    """Actions a controller predicted, to be played one per period if its inputs are lost."""

    values: list[float] = field(default_factory=list)
    period: float = 0.0
    stamp: float = 0.0  # monotonic time of the last computed action


class ControlService:
    """Runs one controller each period on fresh (extrapolated) inputs."""

    def __init__(
        self,
        record: ControllerRecord,
        controller: Controller,
        inputs: Mapping[str, Subscription],
        outputs: list[Publisher],
        *,
        extrapolation: Mapping[str, str],
        futures: dict[str, FutureActions],
    ) -> None:
        self.record = record
        self.controller = controller
        # Controllers with one value per output (plugins.controllers.multi, D91): looked up once, not per period.
        self._step_outputs: Callable[[Mapping[str, Any], float], Sequence[Any]] | None = getattr(
            controller, "step_outputs", None
        )
        self._future_outputs: Callable[[], Sequence[Any]] | None = getattr(controller, "future_outputs", None)
        self.inputs = dict(inputs)
        self.outputs = outputs
        self.extrapolation = dict(extrapolation)
        self.futures = futures
        self.active = record.active
        self.last_output: Any = None  # a tuple for controllers with one value per output
        self.skipped = 0
        self.since = time.monotonic()
        self.optional: Controller | None = None  # the advanced part, run when the CPU allows (§3.1.2.8)
        self.optional_used = 0
        self._pending: tuple[Any, list[Any]] | None = None
        self._inputs: dict[str, float] | None = None
        self._optional_ran = False  # did the optional part give the previous period's output
        self._optional_now = False

    def stale_after(self, subscription: Subscription) -> float:
        """An input older than this is lost: three controller periods, or the topic's lifespan."""
        return stale_after(subscription.qos, self.record.period)

    def read_inputs(self) -> dict[str, Any] | None:
        """The latest value of each input, extrapolated to now by its ``Input/@extrapolation``.

        Returns:
            The values by role, or None when a required input is stale (a missing setpoint is allowed).
        """
        now = time.time()
        values: dict[str, Any] = {}
        for role, subscription in self.inputs.items():
            history = subscription.history()
            if not history or now - (history[-1].stamp - history[-1].offset) > self.stale_after(subscription):
                if role == "setpoint":
                    continue  # a missing setpoint means the controller's default (zero) setpoint
                return None
            if not isinstance(history[-1].value, int | float):  # a message (mapping) or a vector: held as is
                value = history[-1].value  # a local publisher may hand an array itself
                values[role] = value if isinstance(value, np.ndarray) else codec.decode(value)
                continue
            samples = [(s.stamp - s.offset, float(s.value)) for s in history[-3:]]
            values[role] = extrapolate(samples, now, self.extrapolation.get(role, "hold"))
        return values

    def tick(self) -> None:
        """One period: the required part, then publish (what the scheduler runs without an optional part)."""
        self.compute()
        self.publish()

    def compute(self) -> None:
        """The required part: the basic control law's action, held until ``publish``."""
        self._pending = None
        self._inputs = None
        self._optional_now = False
        if not self.active:
            return
        inputs = self.read_inputs()
        if inputs is None:
            self.skipped += 1  # the actuation service notices the silence and plays stored actions
            return
        self._inputs = inputs
        if self._step_outputs is not None and self._future_outputs is not None:
            row = tuple(self._step_outputs(inputs, self.record.period))
            self._pending = (row, list(self._future_outputs()))
            return
        action = self.controller.step(inputs, self.record.period)
        self._pending = (action, list(self.controller.future()))

    def compute_optional(self) -> None:
        """The optional part: when it runs, the advanced law's action replaces the basic one."""
        if self.optional is None or self._inputs is None or self._pending is None:
            return
        if not self._optional_ran and self.last_output is not None:
            self.optional.bumpless(self.last_output)  # it sat out some periods: start from the output
        action = self.optional.step(self._inputs, self.record.period)
        self._pending = (action, list(self.optional.future()) or self._pending[1])
        self._optional_now = True
        self.optional_used += 1

    def publish(self) -> None:
        """Publish the pending action on every output, with its predicted future actions (§3.1.2.2)."""
        self._optional_ran = self._optional_now
        if self._pending is None:
            return
        action, future_values = self._pending
        self.last_output = action
        stamp, now = time.time(), time.monotonic()
        if isinstance(action, tuple):  # one value, and one column of the future rows, per output
            for index, publisher in enumerate(self.outputs):
                column = [row[index] for row in future_values if isinstance(row[index], int | float)]
                self.futures[publisher.qos.name] = FutureActions(column, self.record.period, now)
                publisher.publish(action[index], stamp=stamp)
            return
        future = FutureActions(future_values, self.record.period, now)
        for publisher in self.outputs:
            self.futures[publisher.qos.name] = future
            publisher.publish(action, stamp=stamp)

    def activate(self, output: float | None) -> None:
        """Take over the outputs, starting from the current output (bumpless transfer)."""
        if output is not None:
            self.controller.bumpless(output)
        self.active = True
        self.since = time.monotonic()

    def deactivate(self) -> None:
        """Give the outputs up (controller switching, §3.1.2.7)."""
        self.active = False


class ActuationService:
    """Drives a channel from commands, within bounds and rate limits, and fails safe when they stop."""

    def __init__(
        self,
        record: Actuator,
        backend: Backend,
        inverse: Chain,
        futures: Mapping[str, FutureActions],
        report: Callable[[str, dict[str, Any]], None],
    ) -> None:
        self.record = record
        self.backend = backend
        self.inverse = inverse
        self.futures = futures
        self.report = report
        self.mode = "waiting"  # waiting → commanded → stored → fallback → safe
        self.value: float | None = None
        self.out_of_range = 0
        self._last_command = 0.0
        self._last_drive = 0.0
        self._degraded_since = 0.0
        self._last_range_report = -1e9
        self.latched = False
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ commands

    def command(self, value: Any) -> None:
        """A command arrived on the actuator's topic (ignored once a safe stop is latched)."""
        with self._lock:
            if self.latched:
                return
            self._last_command = time.monotonic()
            if self.mode != "commanded":
                self.mode = "commanded"
            self._drive(value)

    def tick(self) -> None:
        """Watchdog: commands stale → stored actions → fallback sequence → safe value."""
        with self._lock:
            if self.mode == "waiting" or (self.mode == "safe" and self.value == self.record.safe_value):
                return
            now = time.monotonic()
            if self.mode == "commanded" and now - self._last_command <= self.record.command_timeout:
                return
            if self.mode == "commanded":
                self.mode = "stored"
                self._degraded_since = now
                self.report("commands-stale", {"actuator": self.record.name, "age_s": now - self._last_command})
            value = self._degraded_value(now)
            self._drive(value)

    def _degraded_value(self, now: float) -> float:
        future = self.futures.get(self.record.topic)
        if self.mode == "stored" and future is not None and future.values and future.period > 0:
            index = int((now - future.stamp) / future.period) - 1
            if 0 <= index < len(future.values):
                return future.values[index]
        if self.mode == "stored":
            self.mode = "fallback"
            self._degraded_since = now
        if self.mode == "fallback" and self.record.fallback is not None:
            elapsed = now - self._degraded_since
            for action in self.record.fallback.actions:
                if elapsed < action.duration:
                    return action.value
                elapsed -= action.duration
        if self.mode != "safe":
            self.mode = "safe"
            self.report("safe-stop", {"actuator": self.record.name, "value": self.record.safe_value})
        return self.record.safe_value

    def safe_stop(self) -> None:
        """Drive the safe value now, without rate limit, and hold it: later commands are ignored.

        Used on shutdown and by safe-stop alarms; a late command arriving over the network must
        not drive the channel again. (Stale commands, by contrast, end in a safe value that
        fresh commands may leave.)
        """
        with self._lock:
            self.latched = True
            self.mode = "safe"
            self._write(self.record.safe_value)
            self.report("safe-stop", {"actuator": self.record.name, "value": self.record.safe_value})

    # ------------------------------------------------------------------ driving

    def _drive(self, value: Any) -> None:
        record = self.record
        try:
            target = float(value)
        except (TypeError, ValueError):
            self.report("bad-command", {"actuator": record.name, "value": repr(value)[:60]})
            return
        if target != target or not record.min <= target <= record.max:
            self.out_of_range += 1
            action = record.on_out_of_range
            now = time.monotonic()
            if now - self._last_range_report >= 1.0:  # every time counted, reported at most once a second
                self._last_range_report = now
                self.report(
                    "out-of-range",
                    {"actuator": record.name, "value": target, "action": action, "count": self.out_of_range},
                )
            if action == "reject" or target != target:
                return
            target = min(max(target, record.min), record.max)
        now = time.monotonic()
        if record.rate_limit is not None and self.value is not None:
            step = record.rate_limit * max(now - self._last_drive, 0.0)
            target = min(max(target, self.value - step), self.value + step)
        self._last_drive = now
        self._write(target)

    def _write(self, target: float) -> None:
        self.value = target
        raw = self.inverse(target, time.monotonic())
        channel = self.backend.channel
        if channel.min is not None:
            raw = max(raw, channel.min)
        if channel.max is not None:
            raw = min(raw, channel.max)
        self.backend.write(raw)
