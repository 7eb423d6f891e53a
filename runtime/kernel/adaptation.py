"""The built-in adaptation steps (§3.1.2.1, §3.1.2.3) and the chains built from them.

``build_chain(adaptation, registry, inverse=False)`` applies the steps in document order. That is
what both services need: kernel.xsd says an Adaptation's functions are "applied in order: raw to
engineering units for a sensor, engineering to raw units for an actuator", and the actuator of
configs/examples/adaptation_chain.xml is written that way (Deadband in watts, Linear watts→duty,
Clamp in duty).

``inverse=True`` builds the mathematical inverse of the chain (raw ↔ engineering the other way):
the steps in reverse order, each replaced by its inverse —

- Linear: ``(y − offset) / gain``; gain 0 has no inverse.
- Polynomial: of degree 1, the linear inverse; of degree 0 or above 1 (no unique or closed-form
  inverse) none.
- Lookup: the table with x and y swapped when y is strictly monotonic (clamped at the ends like
  the forward table); a non-monotonic table has none.
- Clamp, Deadband: act as themselves. Both are idempotent projections (``f(f(y)) = f(y)``), so
  ``f`` is its own right inverse: ``forward(f(y)) = y`` for every value the step can produce and
  the nearest producible value otherwise; Clamp keeps its bound in the inverse direction.
- LowPass, MovingAverage, Median: pass through. Their steady-state gain is 1, so the identity is
  their steady-state inverse; undoing their dynamics (deconvolution) would amplify noise.
- Function: the plugin's ``inverse()`` when it is a :class:`Step`, otherwise none.

A step without an inverse in an inverse chain, a Lookup whose x does not strictly increase and a
Function plugin's ParamError are ConfigErrors located at the step. A Function plugin class is an
AdaptationFunction constructed with the step's Params (a tuple of Param records).
"""

from __future__ import annotations

import bisect
import math
import statistics
from collections import deque
from collections.abc import Sequence

from ckmconf.binding import Record
from ckmconf.errors import ConfigError
from ckmconf.model import adaptation as model
from runtime.kernel.interfaces import AdaptationFunction
from runtime.registry import Registry


class NotInvertibleError(ValueError):
    """A step asked for its inverse has none."""


class Step(AdaptationFunction):
    """An adaptation function that may know its inverse (Function plugins may subclass it too)."""

    def inverse(self) -> AdaptationFunction:
        """The step that undoes this one (see the module docstring for the rules)."""
        raise NotInvertibleError(f"{type(self).__name__} has no inverse")


class Identity(Step):
    """y = x: what filters become in an inverse chain."""

    def __call__(self, value: float, now: float) -> float:
        """Return ``value`` unchanged."""
        return value

    def inverse(self) -> AdaptationFunction:
        """Itself."""
        return self


class Linear(Step):
    """y = gain·x + offset."""

    def __init__(self, gain: float = 1.0, offset: float = 0.0) -> None:
        self.gain, self.offset = gain, offset

    def __call__(self, value: float, now: float) -> float:
        """Return ``gain·value + offset`` (kernel.xsd ``Linear``)."""
        return self.gain * value + self.offset

    def inverse(self) -> AdaptationFunction:
        """``(y − offset) / gain``.

        Raises:
            NotInvertibleError: the gain is 0.
        """
        if self.gain == 0.0:
            raise NotInvertibleError("Linear with gain 0 has no inverse")
        return Linear(1.0 / self.gain, -self.offset / self.gain)


class Polynomial(Step):
    """y = c0 + c1·x + c2·x² + … (coefficients lowest power first), by Horner's rule."""

    def __init__(self, coefficients: Sequence[float]) -> None:
        coefficients = list(coefficients)
        while len(coefficients) > 1 and coefficients[-1] == 0.0:
            coefficients.pop()  # trailing zeros do not raise the degree
        self.coefficients = tuple(coefficients) or (0.0,)

    def __call__(self, value: float, now: float) -> float:
        """Evaluate the polynomial at ``value`` (Horner's rule; kernel.xsd ``Polynomial``)."""
        result = 0.0
        for c in reversed(self.coefficients):
            result = result * value + c
        return result

    def inverse(self) -> AdaptationFunction:
        """The linear inverse of a degree-1 polynomial.

        Raises:
            NotInvertibleError: the degree is not 1.
        """
        if len(self.coefficients) != 2:
            raise NotInvertibleError(
                f"Polynomial of degree {len(self.coefficients) - 1} has no inverse (only degree 1)"
            )
        c0, c1 = self.coefficients
        return Linear(1.0 / c1, -c0 / c1)


class LowPass(Step):
    """First-order low-pass, cut-off in Hz, exact for inputs held between samples.

    y += (1 − e^{−2π·fc·Δt})·(x − y) with Δt the time since the previous sample, so an irregular
    sampling period does not change the filter's time constant; the first sample passes as is.
    """

    def __init__(self, cutoff: float) -> None:
        if not cutoff > 0.0:
            raise ValueError(f"LowPass cutoff {cutoff} must be greater than 0")
        self.cutoff = cutoff
        self._y = 0.0
        self._t: float | None = None

    def __call__(self, value: float, now: float) -> float:
        """One first-order low-pass step over the time since the last sample (kernel.xsd ``LowPass``)."""
        if self._t is None:
            self._y = value
        else:
            dt = max(0.0, now - self._t)
            self._y += -math.expm1(-2.0 * math.pi * self.cutoff * dt) * (value - self._y)
        self._t = now
        return self._y

    def reset(self) -> None:
        """Forget the filter state: the next sample passes through."""
        self._t = None

    def inverse(self) -> AdaptationFunction:
        """The identity (steady-state gain 1)."""
        return Identity()


class _Window(Step):
    """The last ``window`` samples, for the moving-window filters."""

    def __init__(self, window: int) -> None:
        if window < 1:
            raise ValueError(f"window {window} must be at least 1")
        self.samples: deque[float] = deque(maxlen=window)

    def reset(self) -> None:
        self.samples.clear()

    def inverse(self) -> AdaptationFunction:
        return Identity()


class MovingAverage(_Window):
    """Mean of the last ``window`` samples (of those seen so far, at the start)."""

    def __call__(self, value: float, now: float) -> float:
        """Add ``value`` to the window and return the window's mean (kernel.xsd ``MovingAverage``)."""
        self.samples.append(value)
        return math.fsum(self.samples) / len(self.samples)


class Median(_Window):
    """Median of the last ``window`` samples: rejects spikes shorter than half the window."""

    def __call__(self, value: float, now: float) -> float:
        """Add ``value`` to the window and return the window's median (kernel.xsd ``Median``)."""
        self.samples.append(value)
        return float(statistics.median(self.samples))


class Clamp(Step):
    """Limit to [low, high]."""

    def __init__(self, low: float, high: float) -> None:
        if low > high:
            raise ValueError(f"Clamp min {low} is above max {high}")
        self.low, self.high = low, high

    def __call__(self, value: float, now: float) -> float:
        """Return ``value`` limited to [low, high] (kernel.xsd ``Clamp``)."""
        return min(max(value, self.low), self.high)

    def inverse(self) -> AdaptationFunction:
        """Itself: a projection is its own right inverse."""
        return self


class Deadband(Step):
    """Values from −width to +width become 0; others pass unchanged."""

    def __init__(self, width: float) -> None:
        self.width = width

    def __call__(self, value: float, now: float) -> float:
        """Return 0 within ±width, ``value`` otherwise (kernel.xsd ``Deadband``)."""
        return 0.0 if abs(value) <= self.width else value

    def inverse(self) -> AdaptationFunction:
        """Itself: a projection is its own right inverse."""
        return self


class Lookup(Step):
    """Piece-wise linear table, x strictly increasing, held at the end values outside it."""

    def __init__(self, points: Sequence[tuple[float, float]]) -> None:
        if not points:
            raise ValueError("Lookup needs at least one point")
        self.xs = [float(x) for x, _ in points]
        self.ys = [float(y) for _, y in points]
        if any(b <= a for a, b in zip(self.xs, self.xs[1:], strict=False)):
            raise ValueError("Lookup x values must increase strictly")

    def __call__(self, value: float, now: float) -> float:
        """Interpolate the table at ``value``, held at the end values (kernel.xsd ``Lookup``)."""
        xs, ys = self.xs, self.ys
        if value <= xs[0]:
            return ys[0]
        if value >= xs[-1]:
            return ys[-1]
        i = bisect.bisect_right(xs, value)
        x0, x1, y0, y1 = xs[i - 1], xs[i], ys[i - 1], ys[i]
        return y0 + (y1 - y0) * (value - x0) / (x1 - x0)

    def inverse(self) -> AdaptationFunction:
        """The table with x and y swapped.

        Raises:
            NotInvertibleError: the y values are not strictly monotonic.
        """
        pairs = list(zip(self.ys, self.xs, strict=True))
        if all(b > a for a, b in zip(self.ys, self.ys[1:], strict=False)):
            return Lookup(pairs)
        if all(b < a for a, b in zip(self.ys, self.ys[1:], strict=False)):
            return Lookup(pairs[::-1])
        raise NotInvertibleError("Lookup whose y values are not strictly monotonic has no inverse")


class Chain:
    """Adaptation functions applied in order; callable as ``chain(value, now)``."""

    def __init__(self, functions: Sequence[AdaptationFunction]) -> None:
        self.functions = tuple(functions)

    def __call__(self, value: float, now: float) -> float:
        """Apply the steps in document order (kernel.xsd ``Adaptation``)."""
        for function in self.functions:
            value = function(value, now)
        return value

    def reset(self) -> None:
        """Forget the filters' history (after a gap in the samples, say)."""
        for function in self.functions:
            function.reset()


def _error(record: Record, message: str) -> ConfigError:
    return ConfigError.of(record, message)


def _make(step: model.AdaptationStep, registry: Registry) -> AdaptationFunction:
    match step:
        case model.Linear():
            return Linear(step.gain, step.offset)
        case model.Polynomial():
            return Polynomial(step.coefficients)
        case model.LowPass():
            return LowPass(step.cutoff)
        case model.MovingAverage():
            return MovingAverage(step.window)
        case model.Median():
            return Median(step.window)
        case model.Clamp():
            return Clamp(step.min, step.max)
        case model.Deadband():
            return Deadband(step.width)
        case model.Lookup():
            return Lookup([(p.x, p.y) for p in step.points])
        case model.Function():
            function = registry.resolve("function", step.plugin, step, "plugin")(step.params)
            if not isinstance(function, AdaptationFunction):
                raise _error(step, f"function plugin {step.plugin!r} is not an AdaptationFunction")
            return function
    raise TypeError(f"not an adaptation step: {step!r}")


def build_step(step: model.AdaptationStep, registry: Registry) -> AdaptationFunction:
    """The function for one step record; a Function step's plugin is looked up in ``registry``."""
    try:
        return _make(step, registry)
    except ValueError as exc:  # a bad table, or a Function plugin's ParamError
        raise _error(step, str(exc)) from exc


def build_chain(adaptation: model.Adaptation | None, registry: Registry, *, inverse: bool) -> Chain:
    """The chain of an Adaptation record (no record: the identity); see the module docstring."""
    if adaptation is None:
        return Chain(())
    functions: list[AdaptationFunction] = []
    for step in reversed(adaptation.steps) if inverse else adaptation.steps:
        function = build_step(step, registry)
        if inverse:
            if not isinstance(function, Step):
                raise _error(step, f"function plugin {getattr(step, 'plugin', '?')!r} has no inverse")
            try:
                function = function.inverse()
            except NotInvertibleError as exc:
                raise _error(step, f"{exc}, so it cannot be in an inverse chain") from exc
        functions.append(function)
    return Chain(functions)
