"""``controller.friction-feedforward``: a PID plus Coulomb and viscous friction compensation (§3.1.2.8).

Meant as the ``<Optional>`` part of a ``pid`` controller: when the node has ``minIdle`` CPU to
spare, the control service runs it and its action *replaces* the PID's (``ControlService.
compute_optional``); it takes over bumplessly when it has sat out. So it is a complete law: the
PID of :mod:`plugins.controllers.pid` (same Params; an ``<Optional>`` does not inherit its
controller's Params, so give the same gains, D93) plus the friction the set point will meet,

    u_ff = coulomb·sign(w) + viscous·w     (w: the set point)

with sign(w) replaced by w/deadband for |w| < ``deadband`` so a resting set point gives no chatter.
The feed-forward enters before the output limits and the anti-windup sees it, so the integrator
only supplies what the friction model misses.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import read_params
from runtime.verification.manifest import P, Params

from .common import check_state, clamp, measure_and_setpoint
from .pid import _STATE_KEYS, PID


class FrictionFeedforward(PID):
    """PID with friction feed-forward from the set point (see the module docstring)."""

    FRICTION = Params(
        P("coulomb", 0.0, "Coulomb friction: output added in the direction of the set point.", min=0.0),
        P("viscous", 0.0, "Viscous friction: output added per unit of set point.", min=0.0),
        P("deadband", 1e-3, "Set points smaller than this get a proportional share of coulomb.", above=0.0),
    )
    PARAMS = PID.PARAMS | FRICTION

    def __init__(self, record: ControllerRecord) -> None:
        read_params(record.params, self.PARAMS, owner=f"controller {record.name!r} (friction-feedforward)")
        friction = [p for p in record.params if p.name in self.FRICTION]
        pid_params = tuple(p for p in record.params if p.name not in self.FRICTION)
        super().__init__(dataclasses.replace(record, params=pid_params))
        self.record = record
        self.owner = f"controller {record.name!r} (friction-feedforward)"
        values = read_params(friction, self.FRICTION, owner=self.owner)
        self.coulomb: float = values["coulomb"]
        self.viscous: float = values["viscous"]
        self.deadband: float = values["deadband"]
        self._feedforward = 0.0

    def feedforward(self, setpoint: float) -> float:
        """The friction compensation for a set point."""
        direction = setpoint / self.deadband if abs(setpoint) < self.deadband else (1.0 if setpoint > 0 else -1.0)
        return self.coulomb * direction + self.viscous * setpoint

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """The PID action plus the friction feed-forward of the set point, within the output limits."""
        _, setpoint = measure_and_setpoint(inputs, owner=self.owner)
        feedforward = self.feedforward(setpoint)
        # The PID runs with its limits shifted by the feed-forward, so its anti-windup acts on the total.
        low, high = self.low, self.high
        self.low, self.high = low - feedforward, high - feedforward
        if self._target is not None:
            self._target -= feedforward  # a bumpless take-over sets P + I + D + feed-forward to the output
        try:
            pid = super().step(inputs, dt)
        finally:
            self.low, self.high = low, high
        self._feedforward = feedforward
        self._output = clamp(pid + feedforward, low, high)
        return self._output

    def future(self) -> list[float]:
        """``horizon`` copies of P + I + feed-forward with the last error held (empty before the first step)."""
        if not self._stepped:
            return []
        held = clamp(self.kp * self._error + self._integral + self._feedforward, self.low, self.high)
        return [held] * self.record.horizon

    def state(self) -> dict[str, Any]:
        """The PID's state plus the feed-forward (code delegation, §3.1.2.6)."""
        return {**super().state(), "kind": "friction-feedforward", "feedforward": self._feedforward}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a friction-feedforward controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, "friction-feedforward", (*_STATE_KEYS, "feedforward"))
        super().restore({**state, "kind": "pid"})
        self._feedforward = float(state["feedforward"])
