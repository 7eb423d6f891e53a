"""Adaptation chains (§3.1.2.1, §3.1.2.3) built from a configuration's <Adaptation> through the registry.

Each built-in step (Linear, Polynomial, LowPass, …) is the registered function plugin of the
same name in lower case (``function.linear`` …); a <Function plugin="x"> step is
``function.x``. A plugin class is constructed with its step record. Actuators apply the chain
backwards, each step replaced by its ``inverse()`` (engineering units → raw).
"""

from __future__ import annotations

from collections.abc import Callable

from ckmconf.errors import ConfigError
from ckmconf.model import Adaptation, Function

from ..registry import Registry
from .interfaces import AdaptationFunction, ParamError


def step_kind(step: object) -> str:
    return step.plugin if isinstance(step, Function) else type(step).__name__.lower()


def build_chain(adaptation: Adaptation | None, registry: Registry, *, inverse: bool) -> Callable[[float, float], float]:
    """``chain(value, now)`` applying every step in order (or inverted, in reverse order)."""
    if adaptation is None or not adaptation.steps:
        return lambda value, now: value
    functions: list[AdaptationFunction] = []
    for step in adaptation.steps:
        attr = "plugin" if isinstance(step, Function) else "kind"
        cls = registry.resolve("function", step_kind(step), step, attr)
        try:
            functions.append(cls(step))
        except ParamError as exc:
            loc = step.loc
            raise (ConfigError.at(loc, str(exc)) if loc else ConfigError("<memory>", 1, 1, "/", str(exc))) from None
    if inverse:
        functions = [f.inverse() for f in reversed(functions)]

    def chain(value: float, now: float) -> float:
        for function in functions:
            value = function(value, now)
        return value

    return chain
