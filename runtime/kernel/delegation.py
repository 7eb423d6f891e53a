"""Code delegation (§3.1.2.5–6): a busy node hands a running controller to an idle node.

What moves is data, never code: the controller's registered kind, its configuration (period,
priority, params, horizon, the network names of its input and output topics) and its state
(``Controller.state()``). The receiving node must have the kind registered, or it refuses.

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

import itertools
import logging
import threading
import time
from collections.abc import Mapping
from typing import Any, Protocol

from ckmconf.model import Node, Param
from ckmconf.model.kernel import Controller as ControllerRecord
from ckmconf.model.kernel import ControllerInput, ControllerOutput

from ..network.api import Sample, TopicQoS, Transport
from ..registry import Registry
from .scheduler import Scheduler, Task
from .services import ControlService, FutureActions

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
            to, {"op": "offer", "id": request, "from": runtime.node.name, "controller": describe(runtime, service)}
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
        spec = message["controller"]
        reply: dict[str, Any] = {"id": message["id"]}
        try:
            record = controller_record(spec)
            cls = runtime.registry.resolve("controller", record.kind, record)
            controller = cls(record)
        except Exception as exc:
            self._send(message["from"], reply | {"op": "refuse", "reason": f"cannot run {spec.get('kind')!r}: {exc}"})
            return
        inputs = {role: runtime.transport.subscribe(TopicQoS(topic, history=3)) for topic, role in spec["inputs"]}
        outputs = [runtime.transport.publisher(TopicQoS(topic)) for topic in spec["outputs"]]
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


def describe(runtime: DelegationHost, service: ControlService) -> dict[str, Any]:
    """A controller as plain data: kind, timing, params and the network names of its topics."""
    record = service.record
    return {
        "name": record.name,
        "kind": record.kind,
        "period": record.period,
        "priority": record.priority,
        "horizon": record.horizon,
        "params": [[p.name, p.value] for p in record.params],
        "inputs": [[runtime.topic(p.topic).name, p.role or p.topic] for p in record.inputs],
        "outputs": [runtime.topic(p.topic).name for p in record.outputs],
    }


def controller_record(spec: Mapping[str, Any]) -> ControllerRecord:
    """The Controller record a description stands for (validated by the record's types)."""
    return ControllerRecord(
        name=str(spec["name"]),
        kind=str(spec["kind"]),
        period=float(spec["period"]),
        priority=int(spec["priority"]),
        horizon=int(spec["horizon"]),
        delegable=True,
        params=tuple(Param(name=str(n), value=str(v)) for n, v in spec["params"]),
        inputs=tuple(ControllerInput(topic=str(t), role=str(r)) for t, r in spec["inputs"]),
        outputs=tuple(ControllerOutput(topic=str(t)) for t in spec["outputs"]),
    )
