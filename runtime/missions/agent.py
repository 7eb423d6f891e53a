"""Live missions and plans (thesis §5.2–5.3, Fig. 5.6): one agent's mission on a node, on the network.

:class:`LiveFactory` builds the registered behaviors (category ``behavior``) with contexts bound
to the network: service handles by alias (one per service, shared by the agent's behaviors),
inputs read from their topics or from plan signals, outputs published on their topics.

:class:`AgentRunner` runs one agent of a plan: its mission engine at ``period``; the plan's
signals it emits (``Signal agent=… state=… on=…``) published on their topics, and every signal of
the plan received from its topic (so ``signal('s')`` and ``Input signal="s"`` see it); a
heartbeat on ``/plan/PLAN/agents`` every ``heartbeat`` s with the agent's active state, and the
other agents' heartbeats watched: an agent silent for the plan's ``lostAfter`` is reported lost
(recorded, logged, ``lost`` set) and found again if it comes back. Everything is recorded in the
run directory (:class:`~runtime.missions.recording.RunRecorder`).
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ckmconf.model import System
from ckmconf.model.missions import Plan

from ..network.api import Sample, TopicQoS, Transport
from ..registry import Registry, default_registry
from ..resources import codec
from .behaviors import Behavior, BehaviorContext
from .hfsm import MissionEngine, Signals
from .recording import RunRecorder
from .services import NetworkServiceHandle

LOG = logging.getLogger("ckm.missions")


class LiveFactory:
    """Behaviors of the registry, wired to the network."""

    def __init__(
        self, system: System, transport: Transport, signals: Signals, registry: Registry | None = None
    ) -> None:
        self.system, self.transport, self.signals = system, transport, signals
        self.registry = registry or default_registry()
        self.handles: dict[str, NetworkServiceHandle] = {}
        self._inputs: dict[str, Any] = {}
        self._publishers: dict[str, Any] = {}

    def _handle(self, ref: str) -> NetworkServiceHandle | None:
        if ref not in self.handles:
            found = self.system.service(ref)
            if found is None:
                return None
            self.handles[ref] = NetworkServiceHandle(self.transport, *found)
        return self.handles[ref]

    def _topic_reader(self, topic: str) -> Callable[[], Any]:
        if topic not in self._inputs:
            self._inputs[topic] = self.transport.subscribe(TopicQoS(topic, "ckm/behavior-input"))
        subscription = self._inputs[topic]

        def read() -> Any:
            sample = subscription.latest()
            return None if sample is None else codec.decode(sample.value)

        return read

    def _publisher(self, topic: str) -> Callable[[Any], None]:
        if topic not in self._publishers:
            self._publishers[topic] = self.transport.publisher(TopicQoS(topic, "ckm/behavior-output"))
        publisher = self._publishers[topic]
        return lambda value: publisher.publish(codec.encode(value))

    def __call__(self, behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        record = self.system.behavior(behavior)
        if record is None:
            raise KeyError(f"state {path}: no behavior {behavior!r}")
        services = {u.alias: h for u in record.uses if (h := self._handle(u.service)) is not None}
        inputs: dict[str, Callable[[], Any]] = {}
        for port in record.inputs:
            if port.signal is not None:
                inputs[port.name] = functools.partial(self.signals.values.get, port.signal)
            elif port.topic is not None:
                inputs[port.name] = self._topic_reader(port.topic)
        outputs = {p.name: self._publisher(p.topic) for p in record.outputs if p.topic is not None}
        context = BehaviorContext(services=services, inputs=inputs, outputs=outputs, now=now)
        cls = self.registry.resolve("behavior", record.kind, record)
        instance: Behavior = cls(record, context)
        return instance

    def close(self) -> None:
        for handle in self.handles.values():
            handle.close()


class AgentRunner:
    """One agent of a plan, run on this node (see the module docstring)."""

    def __init__(
        self,
        system: System,
        plan: str,
        agent: str,
        transport: Transport,
        run_dir: Path,
        *,
        registry: Registry | None = None,
        period: float = 0.1,
        heartbeat: float = 0.5,
    ) -> None:
        record = system.plan(plan)
        if record is None:
            raise KeyError(f"no plan {plan!r} (plans: {', '.join(p.name for p in system.plans) or 'none'})")
        me = next((a for a in record.agents if a.name == agent), None)
        if me is None:
            raise KeyError(f"plan {plan!r} has no agent {agent!r}")
        self.plan, self.agent, self.transport = record, me, transport
        self.period, self.heartbeat = period, heartbeat
        self.signals = Signals()
        self.recorder = RunRecorder(run_dir, agent)
        self.factory = LiveFactory(system, transport, self.signals, registry)
        self.lost: set[str] = set()
        self.seen: dict[str, float] = {}
        self._publishers = {s.name: transport.publisher(self._qos(record, s.name)) for s in record.signals}
        for signal in record.signals:
            transport.subscribe(self._qos(record, signal.name), self._received(signal.name))
        self._beat = transport.publisher(TopicQoS(f"/plan/{plan}/agents", "ckm/agent-heartbeat", history=8))
        transport.subscribe(TopicQoS(f"/plan/{plan}/agents", "ckm/agent-heartbeat", history=8), self._on_beat)
        emitters: dict[tuple[str, str], str] = {(s.state, s.on): s.name for s in record.signals if s.agent == agent}
        self.engine = MissionEngine(
            system, me.mission, factory=self.factory, clock=time.monotonic, agent=agent, recorder=self.recorder,
            signals=self.signals, emitters=emitters, on_signal=self._send, plan=plan,
        )  # fmt: skip
        self._stop = threading.Event()
        self._started = 0.0

    @staticmethod
    def _qos(plan: Plan, name: str) -> TopicQoS:
        signal = next(s for s in plan.signals if s.name == name)
        return TopicQoS(plan.signal_topic(signal), signal.type or "ckm/signal", history=4)

    def _send(self, name: str, value: Any) -> None:
        self._publishers[name].publish(codec.encode(value))

    def _received(self, name: str) -> Callable[[Sample], None]:
        def on(sample: Sample) -> None:
            if name in self.signals.values:
                return  # latched already
            try:
                value = codec.decode(sample.value)
            except ValueError:
                LOG.warning("%s: malformed signal %s ignored", self.agent.name, name)
                return
            if isinstance(value, dict) and value.get("agent") == self.agent.name:
                return  # our own emission (agents of one process share a transport)
            self.signals.set(name, value)
            self.recorder.write("signal", name=name, direction="received", value=value)

        return on

    def _on_beat(self, sample: Sample) -> None:
        beat = sample.value
        if isinstance(beat, dict) and isinstance(beat.get("agent"), str) and beat["agent"] != self.agent.name:
            self.seen[beat["agent"]] = time.monotonic()

    def _watch(self) -> None:
        now = time.monotonic()
        for other in self.plan.agents:
            if other.name == self.agent.name:
                continue
            last = self.seen.get(other.name, self._started)
            silent = now - last > self.plan.lost_after
            if silent and other.name not in self.lost:
                self.lost.add(other.name)
                self.recorder.write("agent-lost", lost=other.name)
                LOG.warning("plan %s: agent %s lost (silent for %.1f s)", self.plan.name, other.name, now - last)
            elif not silent and other.name in self.lost:
                self.lost.discard(other.name)
                self.recorder.write("agent-found", found=other.name)

    def _record_qualities(self) -> None:
        """The qualities of the services the agent's behaviors use (the on-line evaluation's inputs)."""
        for ref, handle in self.factory.handles.items():
            measures = handle.measures()
            if measures:
                self.recorder.write("quality", service=ref, client="", measures=measures, scenario=handle.scenario)

    def run(self, duration: float | None = None) -> str | None:
        """Run until the mission ends, ``duration`` passes or :meth:`stop`; the outcome (None if cut short)."""
        self._started = time.monotonic()
        end = None if duration is None else self._started + duration
        self.engine.start()
        next_beat = 0.0
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now >= next_beat:
                    beat = {"agent": self.agent.name, "state": self.engine.active_path(), "t": now}
                    self._beat.publish({**beat, "progress": self.engine.top.progress()})
                    self._watch()
                    self._record_qualities()
                    next_beat = now + self.heartbeat
                if self.engine.step() is not None or (end is not None and now >= end):
                    break
                self._stop.wait(self.period)
        finally:
            if self.engine.outcome is None:
                self.engine.stop("stopped")
            self._beat.publish({"agent": self.agent.name, "state": None, "outcome": self.engine.outcome})
            self.recorder.close()
            self.factory.close()
        return self.engine.outcome

    def stop(self) -> None:
        self._stop.set()
