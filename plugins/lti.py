"""Static, first- and second-order linear plants, discretised exactly (zero-order hold).

The loopback backend simulates these plants and the GPC predicts with them, so a GPC given the
same Params as a loopback plant has an exact model of it. The Params (on a loopback channel or a
``gpc`` controller) are:

- ``order`` 0: ``y = gain·u`` (no dynamics);
- ``order`` 1: ``T·ẏ + y = gain·u`` with ``timeConstant`` T (seconds);
- ``order`` 2: ``ÿ + 2ζω·ẏ + ω²·y = gain·ω²·u`` with ``naturalFrequency`` ω (rad/s) and
  ``damping`` ζ.

The state is ``()``, ``(y,)`` or ``(y, ẏ)``. With the input held over a step of ``h`` seconds the
state moves exactly as ``x' = x_eq + Φ(h)·(x − x_eq)``, ``x_eq`` the equilibrium for that input;
``Φ`` of the second-order plant is a closed-form 2×2 matrix exponential, so there is no
integration error whatever the step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from runtime.kernel.interfaces import ParamError
from runtime.verification.manifest import P, Params

Vector = tuple[float, ...]
Matrix = tuple[Vector, ...]

#: The model Params and their defaults (``order`` is given by the user of the model).
MODEL_SPEC = Params(
    P("gain", 1.0, "Static gain of the plant model (output per unit input)."),
    P("timeConstant", 1.0, "Time constant T of a first-order model.", unit="s", above=0.0),
    P("naturalFrequency", 1.0, "Natural frequency ω of a second-order model.", unit="rad/s", above=0.0),
    P("damping", 0.7, "Damping ratio ζ of a second-order model.", min=0.0),
)
_ORDER_PARAMS = {0: set[str](), 1: {"timeConstant"}, 2: {"naturalFrequency", "damping"}}


@dataclass(frozen=True)
class PlantModel:
    """One plant: its order and coefficients (see the module docstring)."""

    order: int
    gain: float = 1.0
    time_constant: float = 1.0
    natural_frequency: float = 1.0
    damping: float = 0.7

    def equilibrium(self, u: float) -> Vector:
        """The state the plant settles in with the input held at ``u``."""
        return ((), (self.gain * u,), (self.gain * u, 0.0))[self.order]

    def output(self, x: Vector, u: float) -> float:
        """The plant output for state ``x`` and current input ``u``."""
        return x[0] if self.order else self.gain * u

    def transition(self, h: float) -> Matrix:
        """Φ(h) = exp(A·h), the free motion of the state over ``h`` seconds."""
        if self.order == 0:
            return ()
        if self.order == 1:
            return ((math.exp(-h / self.time_constant),),)
        return _expm_second_order(self.natural_frequency, self.damping, h)

    def advance(self, x: Vector, u: float, h: float) -> Vector:
        """The state after ``h`` seconds with the input held at ``u``."""
        if h <= 0.0 or self.order == 0:
            return x
        eq = self.equilibrium(u)
        phi = self.transition(h)
        dev = [xi - ei for xi, ei in zip(x, eq, strict=True)]
        return tuple(e + sum(p * d for p, d in zip(row, dev, strict=True)) for e, row in zip(eq, phi, strict=True))

    def discretise(self, h: float) -> tuple[Matrix, Vector]:
        """(Φ, Γ) of ``x[k+1] = Φ·x[k] + Γ·u[k]`` for the sampling period ``h``."""
        phi = self.transition(h)
        eq = self.equilibrium(1.0)
        gamma = tuple(
            eq[i] - sum(phi[i][j] * eq[j] for j in range(self.order)) for i in range(self.order)
        )  # Γ = (I − Φ)·x_eq(1), since A is invertible
        return phi, gamma

    def difference_equation(self, h: float) -> tuple[list[float], list[float]]:
        """A and B of ``A(q⁻¹)·y[k] = B(q⁻¹)·u[k−1]`` (A monic, B from the u[k−1] term), period ``h``.

        y[k] + a1·y[k−1] + … = b1·u[k−1] + b2·u[k−2] + … — the CARIMA model the GPC uses.
        """
        if self.order == 0:
            raise ValueError("a static plant has no difference equation with a one-period delay")
        phi, gamma = self.discretise(h)
        if self.order == 1:
            return [1.0, -phi[0][0]], [gamma[0]]
        trace = phi[0][0] + phi[1][1]
        det = phi[0][0] * phi[1][1] - phi[0][1] * phi[1][0]
        # y/u = C·adj(zI − Φ)·Γ / det(zI − Φ) with C = [1, 0].
        return [1.0, -trace, det], [gamma[0], phi[0][1] * gamma[1] - phi[1][1] * gamma[0]]


def _expm_second_order(omega: float, zeta: float, h: float) -> Matrix:
    """exp(A·h) for A = [[0, 1], [−ω², −2ζω]], in closed form.

    With s = −ζω and M = A − s·I, M² = δ·I where δ = ω²(ζ² − 1), so
    exp(A·h) = e^{s·h}·(c·I + σ·M) with c = cosh(√δ·h), σ = sinh(√δ·h)/√δ (cos and sin when δ < 0).
    """
    s = -zeta * omega
    delta = omega * omega * (zeta * zeta - 1.0)
    if abs(delta) * h * h < 1e-10:  # critically damped (or nearly): series of cosh and sinh/√δ
        c, sigma = 1.0 + delta * h * h / 2.0, h * (1.0 + delta * h * h / 6.0)
    elif delta > 0.0:
        r = math.sqrt(delta)
        c, sigma = math.cosh(r * h), math.sinh(r * h) / r
    else:
        r = math.sqrt(-delta)
        c, sigma = math.cos(r * h), math.sin(r * h) / r
    e = math.exp(s * h)
    m = ((-s, 1.0), (-omega * omega, -2.0 * zeta * omega - s))
    return (
        (e * (c + sigma * m[0][0]), e * sigma * m[0][1]),
        (e * sigma * m[1][0], e * (c + sigma * m[1][1])),
    )


def model_from_params(
    given: Mapping[str, Any], *, owner: str, orders: tuple[int, ...], default_order: int
) -> PlantModel:
    """A PlantModel from typed Params actually given (``order`` plus MODEL_SPEC names).

    Raises ParamError for an order outside ``orders``, a Param of another order (``damping`` on a
    first-order plant…) or a value out of range.
    """
    order = int(given.get("order", default_order))
    if order not in orders:
        raise ParamError(f"{owner}: parameter 'order' = {order} must be one of {', '.join(map(str, orders))}")
    stray = sorted(set(given) & (set().union(*_ORDER_PARAMS.values()) - _ORDER_PARAMS[order]))
    if stray:
        raise ParamError(f"{owner}: parameter {stray[0]!r} does not apply to a plant of order {order}")
    values = {**MODEL_SPEC, **{k: v for k, v in given.items() if k in MODEL_SPEC}}
    for name, value in values.items():
        if not math.isfinite(value):
            raise ParamError(f"{owner}: parameter {name!r} = {value} must be finite")
    for name in ("timeConstant", "naturalFrequency"):
        if values[name] <= 0.0:
            raise ParamError(f"{owner}: parameter {name!r} = {values[name]} must be greater than 0")
    if values["damping"] < 0.0:
        raise ParamError(f"{owner}: parameter 'damping' = {values['damping']} must not be negative")
    return PlantModel(
        order=order,
        gain=values["gain"],
        time_constant=values["timeConstant"],
        natural_frequency=values["naturalFrequency"],
        damping=values["damping"],
    )
