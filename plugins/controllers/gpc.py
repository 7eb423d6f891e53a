"""``controller.gpc``: Generalized Predictive Control (Clarke et al.), the predictive law of §3.1.2.2.

The plant model is a :mod:`plugins.lti` plant (Params ``order`` 1 or 2, ``gain``,
``timeConstant`` or ``naturalFrequency``/``damping``: the loopback plant's Params), discretised
exactly at the controller's ``period`` into ``A(q⁻¹)·y[k] = B(q⁻¹)·u[k−1]``. As in GPC the
disturbance is integrated (CARIMA), so predictions are made from the measured outputs and the
input *increments* Δu: a constant disturbance or a wrong model gain leaves no steady-state error.

Each step, with N = ``predictionHorizon`` (default: the controller's ``horizon``), Nu =
``controlHorizon`` (default N) and λ = ``lambda`` (default 0.1):

    minimise  Σ_{j=1..N} (ŷ[k+j] − w)² + λ·Σ_{i=0..Nu−1} Δu[k+i]²,   ŷ = f + G·Δu

where w is the set point (held over the horizon), f the free response (all future Δu = 0) and G
the N×Nu matrix of step-response coefficients. The unconstrained least-squares solution
Δu = (GᵀG + λI)⁻¹·Gᵀ·(w − f) uses a gain matrix computed once. The first move is applied (clamped
to ``outputMin``/``outputMax`` or ±``outputLimit``; the clamped move is what the model
remembers); the rest of the sequence, held at its last value beyond Nu, is stored, and
``future()`` returns its ``horizon`` values u[k+1…k+horizon] for the actuation service to play if
the inputs are lost. The model is sampled at ``period``; ``dt`` jitter is not modelled.

Inputs by role: ``measure`` (required), ``setpoint`` (0 when absent); others are ignored.
``bumpless(u)`` makes ``u`` the previous input the next increment starts from (GPC acts on
increments, so control continues from it) and forgets the output history, which may be stale.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ckmconf.model import params_dict
from ckmconf.model.kernel import Controller as ControllerRecord
from plugins.lti import MODEL_SPEC, model_from_params
from runtime.kernel.interfaces import Controller, ParamError, read_params
from runtime.verification.manifest import P, Params

from .common import LIMIT_SPEC, check_state, clamp, finite, measure_and_setpoint, output_limits


class GPC(Controller):
    """Generalized Predictive Control with a first- or second-order plant model (see the module docstring)."""

    PARAMS = (
        Params(P("order", 1, "Order of the plant model.", choices=(1, 2)))
        | MODEL_SPEC
        | Params(
            P("predictionHorizon", None, "Prediction horizon N (default: the controller's horizon).", type=int, min=1),
            P("controlHorizon", None, "Control horizon Nu, from 1 to N (default: N).", type=int, min=1),
            P("lambda", 0.1, "Weight λ of the control increments in the cost.", min=0.0),
        )
        | LIMIT_SPEC
    )

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)
        self.owner = f"controller {record.name!r} (gpc)"
        horizon = {"predictionHorizon": record.horizon}
        values = read_params(record.params, self.PARAMS, owner=self.owner, defaults=horizon)
        given = params_dict(record.params)
        self.model = model_from_params(
            {k: values[k] for k in given if k in MODEL_SPEC or k == "order"},
            owner=self.owner,
            orders=(1, 2),
            default_order=1,
        )
        self.low, self.high = output_limits(values, given, owner=self.owner)
        finite(values, ("lambda",), owner=self.owner)
        n = values["predictionHorizon"]
        nu = values["controlHorizon"] if "controlHorizon" in given else n
        if n < 1:
            raise ParamError(f"{self.owner}: parameter 'predictionHorizon' = {n} must be at least 1")
        if not 1 <= nu <= n:
            raise ParamError(f"{self.owner}: parameter 'controlHorizon' = {nu} must be from 1 to {n}")
        if values["lambda"] < 0.0:
            raise ParamError(f"{self.owner}: parameter 'lambda' = {values['lambda']} must not be negative")
        a, self.b = self.model.difference_equation(record.period)
        self.a_tilde = np.convolve(a, [1.0, -1.0])  # Δ·A: the integrated-disturbance (CARIMA) model
        self.n, self.nu, self.lam = n, nu, float(values["lambda"])
        g = self._simulate([0.0] * (len(self.a_tilde) - 1), [1.0, *[0.0] * len(self.b)], n)
        big_g = np.array([[g[j - i] if j >= i else 0.0 for i in range(nu)] for j in range(n)])
        self.gain_matrix = np.linalg.solve(big_g.T @ big_g + self.lam * np.eye(nu), big_g.T)  # Nu×N
        self._y: list[float] = []  # y[k], y[k−1], … (empty: not started)
        self._du: list[float] = [0.0] * len(self.b)  # Δu[k−1], Δu[k−2], …
        self._u = 0.0  # u[k−1]
        self._plan: list[float] = []

    def _simulate(self, ys: list[float], dus: list[float], steps: int) -> list[float]:
        """Outputs y[k+1…k+steps] of the incremental model from outputs ``ys`` (newest first) and
        increments ``dus`` = Δu[k], Δu[k−1], … (future increments beyond them are 0)."""
        out: list[float] = []
        a_tail, b = self.a_tilde[1:], self.b
        for _ in range(steps):
            y = -sum(ai * yi for ai, yi in zip(a_tail, ys, strict=False))
            y += sum(bi * di for bi, di in zip(b, dus, strict=False))
            out.append(float(y))
            ys, dus = [float(y), *ys[:-1]], [0.0, *dus[:-1]]
        return out

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        """One GPC step: the first move of the optimal increment sequence, clamped (see the module docstring)."""
        measure, setpoint = measure_and_setpoint(inputs, owner=self.owner)
        depth = len(self.a_tilde) - 1
        self._y = [measure, *self._y[: depth - 1]] if self._y else [measure] * depth  # at rest when new
        free = np.array(self._simulate(self._y, [0.0, *self._du], self.n))
        moves = self.gain_matrix @ (setpoint - free)
        plan = self._u + np.cumsum(moves)
        applied = clamp(float(plan[0]), self.low, self.high)
        self._du = [applied - self._u, *self._du[:-1]]
        self._u = applied
        tail = [float(u) for u in plan[1:]] + [float(plan[-1])] * max(0, self.record.horizon - len(plan) + 1)
        self._plan = [clamp(u, self.low, self.high) for u in tail[: self.record.horizon]]
        return applied

    def future(self) -> list[float]:
        """The rest of the planned inputs, u[k+1…k+horizon]."""
        return list(self._plan)

    def bumpless(self, output: float) -> None:
        """Continue from input ``output``; forget the output history and the plan."""
        self._u = float(output)
        self._y, self._du, self._plan = [], [0.0] * len(self.b), []

    def state(self) -> dict[str, Any]:
        """Output history, increments, last input and plan (code delegation, §3.1.2.6)."""
        return {"kind": "gpc", "y": list(self._y), "du": list(self._du), "u": self._u, "plan": list(self._plan)}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a GPC controller.

        Raises:
            ValueError: the state is not one, or is of a model of another order.
        """
        check_state(state, "gpc", ("y", "du", "u", "plan"))
        if len(state["du"]) != len(self.b) or len(state["y"]) not in (0, len(self.a_tilde) - 1):
            raise ValueError(f"{self.owner}: the state is of a model of another order")
        self._y = [float(v) for v in state["y"]]
        self._du = [float(v) for v in state["du"]]
        self._u = float(state["u"])
        self._plan = [float(v) for v in state["plan"]]
