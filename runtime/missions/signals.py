"""Plan signals of one agent's missions (thesis §5.3): those received, and those its states send.

A ``<Plan>`` declares each ``<Signal name agent state on>``: agent ``agent`` sends it when its
state ``state`` is entered, done or left (``on``). Received signals are latched in
:class:`Signals` and read by the ``signal('s')`` condition and by a behavior's ``<Input signal=…>``;
:class:`SignalSender` sends the signals the mission engine's states declare, their payloads
checked against the signal's ``type`` (:func:`runtime.missions.payloads.check_payload`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ckmconf.model.kernel import MessageType

from .payloads import check_payload


@dataclass
class Signals:
    """Plan signals received so far (latched: once received, ``signal()`` stays true).

    A signal travels as an envelope ``{"agent", "state", "time", "data"}``; ``data`` is the payload
    the emitting state's behavior wrote on its ``<Output signal=…>`` (:meth:`supply`), None for a
    signal that carries none. A behavior's ``<Input signal=…>`` reads :meth:`data`.
    """

    values: dict[str, Any] = field(default_factory=dict)
    payloads: dict[str, Any] = field(default_factory=dict)
    """Outgoing: what this agent's behaviors supplied for the signals it will emit."""
    arrivals: dict[str, int] = field(default_factory=dict)
    """How many times each signal was latched (what a behavior's ``heard`` counts, D268)."""

    def received(self, name: str) -> bool:
        """True once plan signal ``name`` arrived (the ``signal('name')`` condition, §5.3)."""
        return name in self.values

    def set(self, name: str, value: Any) -> None:
        """Latch the envelope ``value`` of incoming signal ``name``."""
        self.values[name] = value
        self.arrivals[name] = self.arrivals.get(name, 0) + 1

    def count(self, name: str) -> int:
        """How many times signal ``name`` was latched so far (0 before it arrived)."""
        return self.arrivals.get(name, 0)

    def supply(self, name: str, value: Any) -> None:
        """A behavior's ``<Output signal=name>``: the payload of the next emission of ``name``."""
        self.payloads[name] = value

    def data(self, name: str) -> Any:
        """What an ``<Input signal=name>`` reads: the payload, or the envelope of a signal without one."""
        envelope = self.values.get(name)
        if isinstance(envelope, dict) and envelope.get("data") is not None:
            return envelope["data"]
        return envelope


class SignalError(RuntimeError):
    """A signal whose payload does not match its ``type`` (raised in the emitting agent)."""


class SignalSender:
    """Sends the plan signals declared on one agent's states (§5.3), each payload type-checked."""

    def __init__(
        self,
        signals: Signals,
        agent: str,
        *,
        emitters: Mapping[tuple[str, str], str] | None,
        signal_types: Mapping[str, str | None] | None,
        types: Mapping[str, MessageType],
        on_signal: Callable[[str, Any], None] | None,
        record: Callable[..., None],
    ) -> None:
        self.signals, self.agent = signals, agent
        self.emitters = dict(emitters or {})  # (state path below the top, "entry"|"done"|"exit") → signal
        self.signal_types = dict(signal_types or {})  # signal → its <Signal type> (None: no payload required)
        self._types = types
        self.on_signal = on_signal
        self._record = record  # the engine's mission log

    def emit(self, path: str, when: str, now: float, stopping: bool) -> None:
        """Send the signal declared on ``path`` for ``when`` (entry/done/exit); ``stopping``: record, not raise."""
        relative = path.split("/", 1)[1] if "/" in path else path
        name = self.emitters.get((relative, when))
        if name is None:
            return
        data = self.signals.payloads.pop(name, None)
        kind = self.signal_types.get(name)
        if kind is not None:
            problem = check_payload(data, kind, self._types, "payload")
            if data is None:
                problem = f"no payload: the behavior of {relative} wrote nothing on an <Output signal={name!r}>"
            if problem is not None:
                error = f"signal {name!r} (type {kind}) sent by {self.agent} at {relative}: {problem}"
                if stopping:  # stopping after a crash: record it, do not raise a second time
                    self._record("error", error=f"SignalError: {error}", where=relative)
                    return
                raise SignalError(error)
        value = {"agent": self.agent, "state": relative, "time": now, "data": data}
        self.signals.set(name, value)
        self._record("signal", name=name, direction="sent", value=value)
        if self.on_signal is not None:
            self.on_signal(name, value)
