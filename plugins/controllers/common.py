"""What the controllers share: output limits, inputs by role, clamping and rate limits, state checks."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from runtime.kernel.interfaces import ParamError
from runtime.verification.manifest import P, Params

#: Output-limit Params: ``outputMin``/``outputMax``, or ``outputLimit`` for the symmetric ±limit.
LIMIT_SPEC = Params(
    P("outputMin", -math.inf, "Lowest output (with outputMax; not with outputLimit)."),
    P("outputMax", math.inf, "Highest output (with outputMin; not with outputLimit)."),
    P("outputLimit", math.inf, "Symmetric output limit ±outputLimit (instead of outputMin/outputMax).", above=0.0),
)


def output_limits(values: Mapping[str, Any], given: Mapping[str, str], *, owner: str) -> tuple[float, float]:
    """(low, high) from the typed Params ``values``; ``given`` says which were written."""
    if "outputLimit" in given:
        if "outputMin" in given or "outputMax" in given:
            raise ParamError(f"{owner}: give either 'outputLimit' or 'outputMin'/'outputMax', not both")
        if not values["outputLimit"] > 0.0:
            raise ParamError(f"{owner}: parameter 'outputLimit' = {values['outputLimit']} must be greater than 0")
        return -values["outputLimit"], values["outputLimit"]
    low, high = values["outputMin"], values["outputMax"]
    if not low < high:
        raise ParamError(f"{owner}: parameter 'outputMin' = {low} must be less than 'outputMax' = {high}")
    return low, high


def finite(values: Mapping[str, Any], names: tuple[str, ...], *, owner: str) -> None:
    """ParamError unless each named value is a finite number."""
    for name in names:
        if not math.isfinite(values[name]):
            raise ParamError(f"{owner}: parameter {name!r} = {values[name]} must be finite")


def measure_and_setpoint(inputs: Mapping[str, float], *, owner: str) -> tuple[float, float]:
    """The ``measure`` input (required) and the ``setpoint`` (0 when there is none)."""
    if "measure" not in inputs:
        raise KeyError(f"{owner}: no input with role 'measure' (got {', '.join(sorted(inputs)) or 'none'})")
    return float(inputs["measure"]), float(inputs.get("setpoint", 0.0))


def clamp(value: float, low: float, high: float) -> float:
    """``value`` limited to [low, high]."""
    return min(max(value, low), high)


def toward(current: float, target: float, step: float) -> float:
    """``current`` moved toward ``target`` by at most ``step`` (a rate limit)."""
    return current + clamp(target - current, -step, step)


def check_state(state: Mapping[str, Any], kind: str, keys: tuple[str, ...]) -> None:
    """ValueError unless ``state`` came from ``state()`` of a controller of this kind."""
    if state.get("kind") != kind:
        raise ValueError(f"not a {kind} controller state: kind is {state.get('kind')!r}")
    missing = [key for key in keys if key not in state]
    if missing:
        raise ValueError(f"{kind} controller state lacks {', '.join(missing)}")
