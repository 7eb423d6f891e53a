"""Live missions and plans (thesis §5.2–5.3, Fig. 5.6): one agent's mission on a node, on the network.

:class:`LiveFactory` builds the registered behaviors (category ``behavior``) with contexts bound
to the network: service handles by alias (one per service, shared by the agent's behaviors),
inputs read from their topics or from plan signals, outputs published on their topics.

:class:`AgentRunner` runs one agent of a plan: its mission engine at ``period``; the plan's
signals it emits (``Signal agent=… state=… on=…``) published on their topics, and every signal of
the plan received from its topic (so ``signal('s')`` and ``Input signal="s"`` see it); a
heartbeat on ``/plan/PLAN/agents`` every ``heartbeat`` s with the agent's active state, and the
other agents' heartbeats watched: an agent silent for the plan's ``lostAfter`` is reported lost
(recorded, logged, ``lost`` set) and found again if it comes back. An agent whose last heartbeat
carries its outcome has *finished*: it is recorded ``agent-finished`` and never reported lost; a
signal this agent sends it afterwards is recorded ``signal-dropped`` (and the finished agent
drops it without touching its closed recording). ``lost('a')`` in a transition of this agent's
missions is true while agent ``a`` is lost, and for good once ``a`` has finished in a final other
than its success final (the first its mission declares: ``crashed`` and ``stopped`` count as
failures too). Everything is recorded in the run directory
(:class:`~runtime.missions.recording.RunRecorder`).

The agents of a plan meet before their missions start (D208): each sends its heartbeat and waits
until it has heard every other agent (or heard that it finished), at most ``lostAfter``. A signal
is published once, when its state emits it; an agent whose process joined the network later would
not hear it (a fast spotter once signalled before its fetcher's process had linked, and the fetcher
gave up). An agent not heard within ``lostAfter`` is reported lost as soon as the mission starts.

Silence, like every period and timeout of the mission, is measured on the run's clock
(``time.monotonic``, read at each call): under ``ckm-run --time-scale`` :mod:`runtime.simtime`
scales it in every process of the run, so ``lostAfter`` is simulated seconds, as the world's
physics and the behaviors' timeouts are (D165, D177).

Outcomes (issue G, fail loudly): :meth:`AgentRunner.run` returns the top mission's outcome — one
of its finals, ``stopped`` (cut short by :meth:`stop` or ``duration``) — and :attr:`succeeded`
tells whether it is the success final (the first declared). An exception inside the mission
(a behavior, a bad signal payload) ends it with outcome ``crashed``, recorded with the error,
and is raised again from :meth:`run` for the caller.
"""

from __future__ import annotations

import collections
import functools
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ckmconf.model import System
from ckmconf.model.missions import Plan

from ..network.api import Sample, Subscription, TopicQoS, Transport
from ..registry import Registry, default_registry
from ..resources import codec
from .behaviors import Behavior, BehaviorContext
from .hfsm import MissionEngine
from .recording import RunRecorder
from .services import NetworkServiceHandle
from .signals import Signals

LOG = logging.getLogger("ckm.missions")


def _run_clock() -> float:
    """The run's clock, looked up at each call: the scaled one once :mod:`runtime.simtime` is installed."""
    return time.monotonic()


class LiveFactory:
    """Behaviors of the registry, wired to the network: services (§5.1.1), topics and plan signals (§5.3)."""

    def __init__(
        self, system: System, transport: Transport, signals: Signals, registry: Registry | None = None
    ) -> None:
        self.system, self.transport, self.signals = system, transport, signals
        self.registry = registry or default_registry()
        self.handles: dict[str, NetworkServiceHandle] = {}
        self._inputs: dict[str, Subscription] = {}
        self._asking: collections.Counter[Subscription] = collections.Counter()  # active states reading each
        self._lazy_topics = system.lazy_topics()
        self._publishers: dict[str, Any] = {}
        # Every behavior's topics are joined now, not when its state is first entered: a state's
        # one-shot output (SPOT's target) must reach the next state's input, subscribed before it.
        for record in system.behaviors:
            for port in record.inputs:
                if port.topic is not None:
                    self._topic_reader(port.topic)
            for out in record.outputs:
                if out.topic is not None:
                    self._publisher(out.topic)

    def _handle(self, ref: str) -> NetworkServiceHandle | None:
        if ref not in self.handles:
            found = self.system.service(ref)
            if found is None:
                return None
            self.handles[ref] = NetworkServiceHandle(self.transport, *found)
        return self.handles[ref]

    def _topic_reader(self, topic: str) -> Callable[[], Any]:
        if topic not in self._inputs:  # observed only, until a state reading it is entered (D245)
            self._inputs[topic] = self.transport.subscribe(TopicQoS(topic, "ckm/behavior-input"), passive=True)
        subscription = self._inputs[topic]
        # what a lazy producer published before it rested is not news (D249); a one-shot value
        # of any other topic, published before the state reading it was entered, still is (D166)
        fresh = topic in self._lazy_topics

        def read() -> Any:
            sample = subscription.latest(since_ask=fresh)
            return None if sample is None else codec.decode(sample.value)

        return read

    def _topic_count(self, topic: str) -> Callable[[], int]:
        subscription = self._inputs[topic]  # made by _topic_reader
        return lambda: subscription.received

    def _publisher(self, topic: str) -> Callable[[Any], None]:
        if topic not in self._publishers:
            self._publishers[topic] = self.transport.publisher(TopicQoS(topic, "ckm/behavior-output"))
        publisher = self._publishers[topic]
        return lambda value: publisher.publish(codec.encode(value))

    def __call__(self, behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        """Build the behavior of a state (``BehaviorFactory``): registry kind, services by alias, topics and signals."""
        record = self.system.behavior(behavior)
        if record is None:
            raise KeyError(f"state {path}: no behavior {behavior!r}")
        services = {u.alias: h for u in record.uses if (h := self._handle(u.service)) is not None}
        inputs: dict[str, Callable[[], Any]] = {}
        heard: dict[str, Callable[[], int]] = {}
        for port in record.inputs:
            if port.signal is not None:
                inputs[port.name] = functools.partial(self.signals.data, port.signal)
                heard[port.name] = functools.partial(self.signals.count, port.signal)
            elif port.topic is not None:
                inputs[port.name] = self._topic_reader(port.topic)
                heard[port.name] = self._topic_count(port.topic)
        outputs: dict[str, Callable[[Any], None]] = {}
        for out in record.outputs:
            if out.signal is not None:  # the payload of the plan signal this state emits
                outputs[out.name] = functools.partial(self.signals.supply, out.signal)
            elif out.topic is not None:
                outputs[out.name] = self._publisher(out.topic)
        read = [o for handle in services.values() for o in handle.outputs] + [
            self._inputs[port.topic] for port in record.inputs if port.topic is not None
        ]
        context = BehaviorContext(
            services=services, inputs=inputs, outputs=outputs, now=now,
            demand=functools.partial(self._demand, read), heard=heard, environment=self.system.environment,
        )  # fmt: skip
        cls = self.registry.resolve("behavior", record.kind, record)
        instance: Behavior = cls(record, context)
        return instance

    def _demand(self, subscriptions: list[Subscription], wanted: bool) -> None:
        """Ask for what an entered state reads, and stop asking once no active state reads it (D245)."""
        for subscription in subscriptions:
            self._asking[subscription] += 1 if wanted else -1
            subscription.demand(self._asking[subscription] > 0)

    def related(self, ref: str) -> NetworkServiceHandle | None:
        """A service eq. 5.1 weighs that no behavior of this state uses: its published quality."""
        return self._handle(ref)

    def close(self) -> None:
        """Close every service handle the agent's behaviors shared."""
        for handle in self.handles.values():
            handle.close()


class AgentRunner:
    """One agent of a ``<Plan>`` (§5.3), run on this node (see the module docstring).

    Threads: :meth:`run` and everything it calls (the mission engine, its behaviors, the watch of
    the other agents, the recorder) run on the caller's thread, which owns ``seen``, ``finished``,
    ``lost`` and the latched signals. The transport's threads only decode and hand over: a
    heartbeat or a signal is queued and taken in at the agent's next period, in arrival order.
    :meth:`stop` may be called from any thread.
    """

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
        progress: Callable[[str], None] | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        record = system.plan(plan)
        if record is None:
            raise KeyError(f"no plan {plan!r} (plans: {', '.join(p.name for p in system.plans) or 'none'})")
        me = next((a for a in record.agents if a.name == agent), None)
        if me is None:
            raise KeyError(f"plan {plan!r} has no agent {agent!r}")
        self.plan, self.agent, self.transport = record, me, transport
        self.period, self.heartbeat = period, heartbeat
        self.clock = clock or _run_clock
        successes = {a.name: system.mission(a.mission) for a in record.agents}
        self._others = {a.name for a in record.agents} - {agent}
        self._successes = {name: m.finals[0].name for name, m in successes.items() if m is not None and m.finals}
        self.progress = progress  # told each change of active state, as one line (issue K: a run shows how it goes)
        self._shown: str | None = None
        self.signals = Signals()
        self.recorder = RunRecorder(run_dir, agent)
        self.factory = LiveFactory(system, transport, self.signals, registry)
        self.lost: set[str] = set()
        self.finished: dict[str, str | None] = {}  # agent → the outcome its last heartbeat gave
        self.seen: dict[str, float] = {}
        self.outcome: str | None = None
        self.error: BaseException | None = None
        self._done = threading.Event()  # this agent's mission has ended: late signals are dropped
        # what the transport's threads hand to the agent's thread (deque appends and pops are atomic)
        self._inbox: collections.deque[Callable[[], None]] = collections.deque()
        self._publishers = {s.name: transport.publisher(self._qos(record, s.name)) for s in record.signals}
        for signal in record.signals:
            transport.subscribe(self._qos(record, signal.name), self._received(signal.name))
        self._beat = transport.publisher(TopicQoS(f"/plan/{plan}/agents", "ckm/agent-heartbeat", history=8))
        transport.subscribe(TopicQoS(f"/plan/{plan}/agents", "ckm/agent-heartbeat", history=8), self._on_beat)
        emitters: dict[tuple[str, str], str] = {(s.state, s.on): s.name for s in record.signals if s.agent == agent}
        self.engine = MissionEngine(
            system, me.mission, factory=self.factory, clock=self.clock, agent=agent, recorder=self.recorder,
            signals=self.signals, emitters=emitters, on_signal=self._send, plan=plan,
            signal_types={s.name: s.type for s in record.signals}, related=self.factory.related,
            lost=self.agent_lost,
        )  # fmt: skip
        finals = self.engine.record_mission.finals
        self._success = finals[0].name if finals else None
        self._stop = threading.Event()
        self._started = 0.0

    @staticmethod
    def _qos(plan: Plan, name: str) -> TopicQoS:
        signal = next(s for s in plan.signals if s.name == name)
        return TopicQoS(plan.signal_topic(signal), signal.type or "ckm/signal", history=4)

    @property
    def succeeded(self) -> bool:
        """True once the mission has ended in its success final (the first declared)."""
        return self.outcome is not None and self.outcome == self._success

    def agent_lost(self, name: str) -> bool:
        """``lost('name')``: the agent is lost now, or finished in a final other than its success final."""
        if name in self.lost:
            return True
        return name in self.finished and self.finished[name] != self._successes.get(name)

    def _send(self, name: str, value: Any) -> None:
        self._publishers[name].publish(codec.encode(value))
        waiting = {d.agent for d in self.plan.dependencies if d.signal == name} or {
            a.name for a in self.plan.agents if a.name != self.agent.name
        }
        for receiver in sorted(waiting & set(self.finished)):
            self.recorder.write("signal-dropped", name=name, to=receiver, outcome=self.finished[receiver])
            LOG.info("plan %s: signal %s reaches %s, which has finished: dropped", self.plan.name, name, receiver)

    def _received(self, name: str) -> Callable[[Sample], None]:
        """The transport's callback for signal ``name``: decoded there, latched on the agent's thread."""

        def on(sample: Sample) -> None:
            try:
                value = codec.decode(sample.value)
            except ValueError:
                LOG.warning("%s: malformed signal %s ignored", self.agent.name, name)
                return
            if isinstance(value, dict) and value.get("agent") == self.agent.name:
                return  # our own emission (agents of one process share a transport)
            if self._done.is_set():
                LOG.info("%s: signal %s arrived after the mission ended: dropped", self.agent.name, name)
                return  # never raise into the sender's thread (one process shares a transport)
            self._inbox.append(functools.partial(self._latch, name, value))

        return on

    def _latch(self, name: str, value: Any) -> None:
        """Latch a received signal (the agent's thread)."""
        if name in self.signals.values:
            return  # latched already
        self.signals.set(name, value)
        self.recorder.write("signal", name=name, direction="received", value=value)

    def _on_beat(self, sample: Sample) -> None:
        """The transport's callback for a heartbeat: the agent's thread takes it in at its next period."""
        beat = sample.value
        if not (isinstance(beat, dict) and beat.get("agent") in self._others):
            return  # not a heartbeat, ours, or from no agent of the plan
        self._inbox.append(functools.partial(self._heard, beat["agent"], beat, self.clock()))

    def _drain(self) -> None:
        """Take in what the transport's threads handed over since the last period, in arrival order."""
        while self._inbox:
            self._inbox.popleft()()

    def _heard(self, other: str, beat: dict[str, Any], at: float) -> None:
        """Agent ``other``'s heartbeat, heard at ``at`` (the agent's thread)."""
        self.seen[other] = at
        if "outcome" in beat and beat.get("state") is None and other not in self.finished:
            outcome = beat["outcome"] if isinstance(beat["outcome"], str) else None
            self.finished[other] = outcome
            self.lost.discard(other)
            self.recorder.write("agent-finished", finished=other, outcome=outcome)
            if outcome != self._successes.get(other):  # lost('other') holds from now on
                LOG.warning("plan %s: agent %s finished in failure (%s)", self.plan.name, other, outcome)
            else:
                LOG.info("plan %s: agent %s finished (%s)", self.plan.name, other, outcome)

    def _watch(self) -> None:
        now = self.clock()
        for other in self.plan.agents:
            if other.name == self.agent.name or other.name in self.finished:
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
        """Run until the mission ends, ``duration`` passes or :meth:`stop`; the outcome.

        Returns a final of the top mission, or ``stopped`` when cut short. An exception in the
        mission ends it as ``crashed`` (recorded with the error, kept in :attr:`error`) and is
        raised again.
        """
        self._started = self.clock()
        end = None if duration is None else self._started + duration
        next_beat = 0.0
        try:
            self._meet()
            self.engine.start()
            while not self._stop.is_set():
                self._drain()
                now = self.clock()
                if now >= next_beat:
                    beat = {"agent": self.agent.name, "state": self.engine.active_path(), "t": now}
                    self._beat.publish({**beat, "progress": self.engine.top.progress()})
                    self._watch()
                    self._record_qualities()
                    next_beat = now + self.heartbeat
                if self.engine.step() is not None or (end is not None and now >= end):
                    break
                self._show(now)
                self._stop.wait(self.period)
            self.outcome = self.engine.outcome or "stopped"
        except Exception as error:
            self.error, self.outcome = error, "crashed"
            LOG.error("plan %s: agent %s crashed: %s", self.plan.name, self.agent.name, error)
            self.recorder.write("error", error=f"{type(error).__name__}: {error}", where=self.engine.active_path())
            raise
        finally:
            self._finish()
        return self.outcome

    def _meet(self) -> None:
        """Heartbeats until every other agent of the plan is heard (or finished), at most ``lostAfter`` (D208)."""
        while not self._stop.is_set():
            self._drain()
            missing = self._others - set(self.seen) - set(self.finished)
            if not missing or self.clock() - self._started >= self.plan.lost_after:
                if missing:
                    LOG.warning("plan %s: agent %s starts without %s (not heard within lostAfter, %g s)",
                                self.plan.name, self.agent.name, ", ".join(sorted(missing)), self.plan.lost_after)
                return
            self._beat.publish({"agent": self.agent.name, "state": "", "t": self.clock(), "progress": 0.0})
            self._stop.wait(min(self.heartbeat, self.period))

    def _show(self, now: float) -> None:
        """One progress line when the active state changes: agent, elapsed time, state path, mission progress."""
        if self.progress is None:
            return
        path = self.engine.active_path()
        if path == self._shown:
            return
        self._shown = path
        share = self.engine.top.progress()
        line = f"[{now - self._started:7.1f} s] {self.agent.name}: {path or '-'}  ({share:.0%} of the mission)"
        try:
            self.progress(line)
        except Exception:  # a closed terminal must not end the mission
            LOG.exception("agent %s: progress line not shown", self.agent.name)

    def _finish(self) -> None:
        """End the recording with the outcome; each step isolated so that none skips the others."""
        self._done.set()
        outcome = self.outcome or "stopped"
        try:
            if self.engine.outcome is None:
                if self.engine.top.state is not None:
                    self.engine.stop(outcome)
                else:  # crashed before the initial state was entered
                    self.recorder.write("end", outcome=outcome)
        except Exception:
            LOG.exception("agent %s: stopping its mission failed", self.agent.name)
            self.recorder.write("end", outcome=outcome)
        if self.progress is not None:
            try:
                self.progress(f"{self.agent.name}: mission ended: {outcome}")
            except Exception:
                LOG.exception("agent %s: progress line not shown", self.agent.name)
        try:
            self._beat.publish({"agent": self.agent.name, "state": None, "outcome": outcome})
        except Exception:
            LOG.exception("agent %s: the last heartbeat could not be sent", self.agent.name)
        self.recorder.close()
        self.factory.close()

    def stop(self) -> None:
        """Make :meth:`run` return ``stopped`` at its next period, from any thread."""
        self._stop.set()
