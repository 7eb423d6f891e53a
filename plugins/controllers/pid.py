"""``controller.pid``: a PID with anti-windup, derivative on measurement and bumpless transfer.

Params: ``kp`` (default 1), ``ki``, ``kd`` (default 0), ``tau`` (time constant of the derivative's
first-order filter, seconds; 0 = unfiltered), and the output limits ``outputMin``/``outputMax`` or
``outputLimit`` (±limit). Inputs by role: ``measure`` (required) and ``setpoint`` (0 when absent);
other roles are ignored.

- Derivative on measurement: the D term is ``−kd·d(measure)/dt``, so a set-point step gives no kick.
- Anti-windup: the integrator stops while the output is saturated in the direction it would grow,
  and never integrates beyond [outputMin, outputMax] on its own.
- ``bumpless(u)``: the next ``step`` sets the integrator to ``u − P − D`` so it outputs exactly
  ``u`` (then integrates normally); the derivative history is dropped, as it may be stale.
- ``future()``: ``horizon`` copies of ``P + I`` with the last error held, the integrator frozen
  (integrating an error nobody measures is how windup starts) and the derivative 0 (the measure
  is assumed to stay). Empty before the first step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model import params_dict
from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import Controller, ParamError, read_params
from runtime.verification.manifest import P, Params

from .common import LIMIT_SPEC, check_state, clamp, finite, measure_and_setpoint, output_limits

_STATE_KEYS = ("integral", "previous", "derivative", "error", "output", "target", "stepped")


class PID(Controller):
    """A PID with anti-windup, derivative on measurement and bumpless transfer (see the module docstring)."""

    PARAMS = (
        Params(
            P("kp", 1.0, "Proportional gain."),
            P("ki", 0.0, "Integral gain.", unit="1/s"),
            P("kd", 0.0, "Derivative gain (on the measure).", unit="s"),
            P("tau", 0.0, "Time constant of the derivative's low-pass filter (0: unfiltered).", unit="s", min=0.0),
        )
        | LIMIT_SPEC
    )

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.owner = f"controller {record.name!r} (pid)"
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        finite(values, ("kp", "ki", "kd", "tau"), owner=self.owner)
        if values["tau"] < 0.0:
            raise ParamError(f"{self.owner}: parameter 'tau' = {values['tau']} must not be negative")
        self.kp: float = values["kp"]
        self.ki: float = values["ki"]
        self.kd: float = values["kd"]
        self.tau: float = values["tau"]
        self.low, self.high = output_limits(values, params_dict(record.params), owner=self.owner)
        self._integral = 0.0
        self._previous: float | None = None  # the last measure, for the derivative
        self._derivative = 0.0  # filtered d(measure)/dt
        self._error = 0.0
        self._output = 0.0
        self._target: float | None = None  # bumpless output pending for the next step
        self._stepped = False

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """One PID step (see the module docstring): P + I + D, clamped, with anti-windup."""
        measure, setpoint = measure_and_setpoint(inputs, owner=self.owner)
        dt = dt if dt > 0.0 else self.record.period
        if self._previous is not None:
            rate = (measure - self._previous) / dt
            alpha = -math.expm1(-dt / self.tau) if self.tau > 0.0 else 1.0
            self._derivative += alpha * (rate - self._derivative)
        self._previous = measure
        error = setpoint - measure
        p, d = self.kp * error, -self.kd * self._derivative
        if self._target is not None:
            self._integral, self._target = self._target - p - d, None
        else:
            self._integral = self._integrate(self.ki * error * dt, p + d)
        self._error, self._stepped = error, True
        self._output = clamp(p + self._integral + d, self.low, self.high)
        return self._output

    def _integrate(self, increment: float, others: float) -> float:
        """The integrator after ``increment``, with anti-windup (``others`` = P + D)."""
        integral = self._integral
        unclamped = others + integral + increment
        if (unclamped > self.high and increment > 0.0) or (unclamped < self.low and increment < 0.0):
            return integral  # saturated: do not wind up further
        moved = integral + increment
        return max(min(moved, max(integral, self.high)), min(integral, self.low))

    def future(self) -> list[float]:
        """``horizon`` copies of P + I with the last error held (empty before the first step)."""
        if not self._stepped:
            return []
        held = clamp(self.kp * self._error + self._integral, self.low, self.high)
        return [held] * self.record.horizon

    def bumpless(self, output: float) -> None:
        """The next step outputs exactly ``output`` (the integrator takes up the difference)."""
        self._target = float(output)
        self._previous, self._derivative = None, 0.0

    def state(self) -> dict[str, Any]:
        """Integrator, derivative filter, last error and output (code delegation, §3.1.2.6)."""
        return {
            "kind": "pid",
            "integral": self._integral,
            "previous": self._previous,
            "derivative": self._derivative,
            "error": self._error,
            "output": self._output,
            "target": self._target,
            "stepped": self._stepped,
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a PID controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, "pid", _STATE_KEYS)
        self._integral = float(state["integral"])
        self._previous = None if state["previous"] is None else float(state["previous"])
        self._derivative = float(state["derivative"])
        self._error = float(state["error"])
        self._output = float(state["output"])
        self._target = None if state["target"] is None else float(state["target"])
        self._stepped = bool(state["stepped"])
