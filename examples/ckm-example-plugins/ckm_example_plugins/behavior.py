"""``behavior.wait-above``: done once an input exceeds a threshold (the behavior example).

The behavior reads its ``<Input>`` named by the ``input`` Param (default: its first input), a
number published on a topic; progress is how close the value is to ``threshold`` (traceable
from ``start``, the value at which progress is 0).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.manifest import NUMBER, REQUIRED, P, Params, Ports


class WaitAbove(Behavior):
    """Waits until a numeric input is above a threshold."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("threshold", REQUIRED, "Value the input must exceed.", type=float),
        P("start", 0.0, "Input value at which progress is 0."),
        P("input", "", "Name of the input to watch (default: the first one)."),
    )
    PORTS: ClassVar[Ports] = Ports(inputs={"*": NUMBER})

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        names = [port.name for port in record.inputs]
        self.input = self.params["input"] or (names[0] if names else "")
        if self.input not in names:
            raise ParamError(f"{self.owner}: input {self.input!r} is not one of its inputs ({names})")

    def step(self) -> BehaviorStatus:
        """One tick of the behavior (ckm.xsd ``Behavior``, §5.1): progress toward the threshold, done above it."""
        value = self.read(self.input)
        if value is None:
            return BehaviorStatus(progress=0.0, detail="no value yet")
        threshold, start = self.params["threshold"], self.params["start"]
        span = threshold - start
        progress = 1.0 if span <= 0 else min(1.0, max(0.0, (float(value) - start) / span))
        return BehaviorStatus(progress=progress, done=float(value) > threshold)
