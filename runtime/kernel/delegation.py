"""Code delegation (§3.1.2.5–6): a busy node hands a running controller to an idle node.

What moves is data, never code: the controller's configuration and its state
(``Controller.state()``). The configuration travels as configuration text, written and read by
ckmconf (:mod:`ckmconf.fragment`): a ``<Part>`` with the giver's ``<Node>`` holding the topics the
controller uses and the ``<Controller>`` (kind, period, priority, horizon, params, inputs and
outputs), checked on arrival by the loader's own validation, so a bad description is refused with
the located message ``ckm-validate`` would give. The taker names the topics as the giver does
(:mod:`.topics`). The receiving node must have the kind registered, or it refuses.

The handover is atomic:

1. OFFER  (giver → taker): the description. The taker builds the controller, inactive.
2. READY  (taker → giver), or REFUSE with the reason.
3. At its next release the giver does not compute: it removes its task and sends GO with the
   state after its last step, its last output and its release grid.
4. The taker restores the state, steps at once — so the period that began at the giver's
   release still gets exactly one output — and continues on the same grid.

So no period goes without an output and no period gets two. Messages travel on
``/ckm/delegation/NODE`` (each node listens on its own); all of it is msgpack-able.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import threading
import time
from collections.abc import Mapping
from typing import Any, Protocol

from ckmconf.errors import ConfigError
from ckmconf.fragment import dumps_node, loads_node
from ckmconf.model import BUILTIN_TYPES, Node, System
from ckmconf.model.kernel import Controller as ControllerRecord

from ..network.api import Sample, TopicQoS, Transport
from ..registry import Registry
from .scheduler import Scheduler, Task
from .services import ControlService, FutureActions
from .topics import declared_topic, topic_qos

LOG = logging.getLogger("ckm.delegation")
_ids = itertools.count(1)


def channel(node: str) -> TopicQoS:
    """The topic on which ``node`` receives delegation messages (code delegation, §3.1.2.6)."""
    return TopicQoS(f"/ckm/delegation/{node}", "delegation", history=16)


class DelegationHost(Protocol):
    """What delegation needs of its node (the kernel's ``NodeRuntime`` is one): the node's record,
    its transport, registry and scheduler, the controllers it runs (given ones leave, taken ones
    join the scheduler), its future actions, its topics' network names and its event log."""

    @property
    def node(self) -> Node:
        """The node's configuration record (kernel.xsd ``NodeType``)."""
        ...

    @property
    def system(self) -> System:
        """The system the node belongs to (its external topics and message types)."""
        ...

    @property
    def transport(self) -> Transport:
        """The node's transport."""
        ...

    @property
    def registry(self) -> Registry:
        """The plugin registry that builds delegated controllers."""
        ...

    @property
    def scheduler(self) -> Scheduler:
        """The node's scheduler, which runs taken controllers."""
        ...

    @property
    def controllers(self) -> dict[str, ControlService]:
        """The node's control services by controller name."""
        ...

    @property
    def futures(self) -> dict[str, FutureActions]:
        """The future actions each controller last published, by output topic."""
        ...

    def topic(self, name: str) -> TopicQoS:
        """The QoS, with the network name, of topic ``name`` as the node sees it."""
        ...

    def report(self, kind: str, detail: dict[str, Any]) -> None:
        """Record a node event (kept, logged and published on the node's alarm topic)."""
        ...


class Delegation:
    """The delegation endpoint of one node: gives its controllers away, takes others'."""

    def __init__(self, runtime: DelegationHost, timeout: float = 5.0) -> None:
        self.runtime = runtime
        self.timeout = timeout
        self.taken: dict[str, ControlService] = {}  # name → service run for another node
        self._pending: dict[int, dict[str, Any]] = {}
        self._answers: dict[int, threading.Event] = {}
        self._out: dict[str, Any] = {}
        transport = runtime.transport
        transport.subscribe(channel(runtime.node.name), self._on_message)

    # ------------------------------------------------------------------ giving

    def give(self, controller: str, to: str) -> bool:
        """Hand ``controller`` to node ``to``; True once the taker runs it, False if refused or timed out."""
        runtime = self.runtime
        service = runtime.controllers.get(controller)
        if service is None or not service.record.delegable:
            raise ValueError(f"controller {controller!r} of node {runtime.node.name!r} is not delegable")
        request = next(_ids)
        answered = self._answers[request] = threading.Event()
        self._send(
            to,
            {
                "op": "offer",
                "id": request,
                "from": runtime.node.name,
                "controller": describe(runtime.node, runtime.system, service.record),
            },
        )
        if not answered.wait(self.timeout):
            self._report("delegation-timeout", controller, to)
            return False
        answer = self._pending.pop(request)
        if answer["op"] != "ready":
            self._report("delegation-refused", controller, to, answer.get("reason", ""))
            return False
        done = threading.Event()
        task_name = f"{runtime.node.name}.{controller}"
        task = runtime.scheduler.tasks[task_name]

        def hand_over() -> None:
            # Runs at the giver's release instead of a control step: this period is the taker's.
            runtime.scheduler.remove(task_name)
            service.deactivate()
            self._send(
                to,
                {
                    "op": "go",
                    "id": request,
                    "from": runtime.node.name,
                    "name": controller,
                    "state": service.controller.state(),
                    "output": service.last_output,
                    "release_wall": time.time(),
                    "period": service.record.period,
                },
            )
            done.set()

        task.optional = task.finish = None  # this release only hands over: nothing else may publish
        task.required = hand_over
        if not done.wait(self.timeout):
            return False
        del runtime.controllers[controller]
        self._report("delegated", controller, to)
        return True

    # ------------------------------------------------------------------ taking

    def _on_message(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict) or "op" not in message:
            return
        try:
            if message["op"] in ("ready", "refuse"):
                self._pending[message["id"]] = message
                event = self._answers.pop(message["id"], None)
                if event is not None:
                    event.set()
            elif message["op"] == "offer":
                self._offer(message)
            elif message["op"] == "go":
                self._go(message)
        except Exception as exc:  # a malformed request must not take the node down
            LOG.warning("ignoring a malformed delegation message: %s", exc)

    def _offer(self, message: Mapping[str, Any]) -> None:
        runtime = self.runtime
        reply: dict[str, Any] = {"id": message["id"]}
        try:
            record, names = controller_of(message["controller"], str(message["from"]))
        except ConfigError as exc:
            self._send(message["from"], reply | {"op": "refuse", "reason": str(exc)})
            return
        try:
            cls = runtime.registry.resolve("controller", record.kind, record)
            controller = cls(record)
        except Exception as exc:
            self._send(message["from"], reply | {"op": "refuse", "reason": f"cannot run {record.kind!r}: {exc}"})
            return
        inputs = {
            p.role or p.topic: runtime.transport.subscribe(TopicQoS(names[p.topic], history=3)) for p in record.inputs
        }
        outputs = [runtime.transport.publisher(TopicQoS(names[p.topic])) for p in record.outputs]
        service = ControlService(record, controller, inputs, outputs, extrapolation={}, futures=runtime.futures)
        service.deactivate()
        self.taken[record.name] = service

        def ready_when_fed() -> None:
            # Ready only once every input has delivered: the first step after GO must have data.
            deadline = time.monotonic() + self.timeout / 2
            for role, subscription in inputs.items():
                if role != "setpoint" and not subscription.wait(1, max(0.0, deadline - time.monotonic())):
                    self._send(message["from"], reply | {"op": "refuse", "reason": f"no data on input {role!r}"})
                    return
            self._send(message["from"], reply | {"op": "ready"})

        threading.Thread(target=ready_when_fed, name="ckm-delegation", daemon=True).start()

    def _go(self, message: Mapping[str, Any]) -> None:
        service = self.taken[message["name"]]
        service.controller.restore(message["state"])
        service.activate(None)
        service.last_output = message["output"]
        service.tick()  # this period's output, right away
        period = float(message["period"])
        # Continue on the giver's grid: its release, in our clocks, plus one period.
        first = time.perf_counter() + (float(message["release_wall"]) + period - time.time())
        name = f"{self.runtime.node.name}.{service.record.name}@{message['from']}"
        self.runtime.scheduler.add(
            Task(name, period, service.tick, priority=service.record.priority), first_release=first
        )
        self._report("took-over", service.record.name, message["from"])

    # ------------------------------------------------------------------ helpers

    def _send(self, node: str, message: dict[str, Any]) -> None:
        publisher = self._out.get(node)
        if publisher is None:
            publisher = self._out[node] = self.runtime.transport.publisher(channel(node))
        publisher.publish(message)

    def _report(self, kind: str, controller: str, peer: str, reason: str = "") -> None:
        self.runtime.report(kind, {"controller": controller, "peer": peer, "reason": reason})


def describe(giver: Node, system: System, controller: ControllerRecord) -> str:
    """A controller as configuration text (:func:`ckmconf.fragment.dumps_node`): the giver's node
    reduced to the controller and the topics (and message types of ``system``) it uses.

    Only what runs moves: the controller leaves its partition, its switches and its optional part
    behind, and runs active and delegable on the taker.
    """
    record = dataclasses.replace(controller, partition=None, active=True, delegable=True, optional=None, switches=())
    used = dict.fromkeys(p.topic for p in (*record.inputs, *record.outputs))
    topics = [t for t in (declared_topic(giver, system, name) for name in used) if t is not None]
    types = {t.type for t in topics} - BUILTIN_TYPES
    node = Node(name=giver.name, kind=giver.kind, topics=tuple(topics), controllers=(record,))
    return dumps_node(node, [m for m in system.message_types if m.name in types])


def controller_of(text: Any, giver: str) -> tuple[ControllerRecord, dict[str, str]]:
    """The Controller record a description stands for, and the network name of each topic it uses.

    The text is checked as the loader checks a file (:func:`ckmconf.fragment.loads_node`).

    Raises:
        ConfigError: not text, or text the loader refuses (located in ``<delegation from GIVER>``), or
            a node fragment that does not hold exactly one delegable controller.
    """
    origin = f"<delegation from {giver}>"
    if not isinstance(text, (str, bytes)):
        raise ConfigError(
            origin, 1, 1, "/", f"a controller description is configuration text, not {type(text).__name__}"
        )
    node = loads_node(text, origin)
    if len(node.controllers) != 1 or not node.controllers[0].delegable:
        raise ConfigError.of(node, "a delegated node fragment holds exactly one delegable Controller")
    names = {t.name: topic_qos(node.name, t).name for t in node.topics}
    return node.controllers[0], names
