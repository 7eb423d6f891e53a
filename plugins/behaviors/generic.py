"""General-purpose behaviors: ``timer``, ``emit`` and ``wait-input``.

Small building blocks any mission can use with no robot: wait a while (traceable progress),
publish a value on an output and end, or wait — untraceable, bounded by the behavior's timeout —
until an input (a topic or a plan signal) has a value.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.manifest import P, Params, Ports


class Timer(Behavior):
    """``behavior.timer``: done after ``duration`` seconds; progress is the share elapsed."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(P("duration", 1.0, "Time until done.", unit="s", above=0.0))

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        if not self.params["duration"] > 0:
            raise ParamError(f"{self.owner}: parameter 'duration' = {self.params['duration']} must be greater than 0")

    def step(self) -> BehaviorStatus:
        """Progress is the share of ``duration`` elapsed; done when it has all passed."""
        share = self.context.now() / self.params["duration"]
        return BehaviorStatus(progress=min(1.0, share), done=share >= 1.0)


class Emit(Behavior):
    """``behavior.emit``: publishes ``value`` (a string Param) on every output once, then is done."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(P("value", "", "The string published on every output."))
    PORTS = Ports(outputs={"*": "string"})

    def start(self) -> None:
        """Publish ``value`` on every output, once, as the state is entered."""
        super().start()
        for port in self.record.outputs:
            self.write(port.name, self.params["value"])

    def step(self) -> BehaviorStatus:
        """Done at once: the outputs were written at start."""
        return BehaviorStatus(progress=1.0, done=True)


class WaitInput(Behavior):
    """``behavior.wait-input``: done as soon as every input has a value (``input`` Param: just that one)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(P("input", "", "Wait for this input only (default: every input)."))

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        names = [p.name for p in record.inputs]
        wanted = self.params["input"]
        if wanted and wanted not in names:
            raise ParamError(f"{self.owner}: parameter 'input' = {wanted!r} is not one of its inputs ({names})")
        self.names = [wanted] if wanted else names
        self.value: Any = None

    def step(self) -> BehaviorStatus:
        """Done as soon as every awaited input has a value; untraceable progress until then."""
        values = [self.read(name) for name in self.names]
        if all(v is not None for v in values):
            self.value = values[0]
            return BehaviorStatus(progress=1.0, done=True)
        return BehaviorStatus(progress=0.0)  # untraceable: the timeout bounds it
