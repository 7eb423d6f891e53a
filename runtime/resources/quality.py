"""Quality measures and policies (thesis §4.2.1.1–4.2.1.2, eq. 4.1–4.5).

A quality measure is a stream of samples ``{Q_i | i = 0..n}`` (eq. 4.1). A policy bounds it,
``lower ≤ Q ≤ upper`` (eq. 4.2), and holds when the measure lies within the bounds with at least
the policy's probability over its last ``window`` samples.

- :func:`empirical_cdf` is eq. 4.3: every sample of the window weighs ``f(Q_i) = 1/n``, so
  ``F(x) = #{Q_i ≤ x} / n``.
- :func:`probability_within` is eq. 4.4. Eq. 4.2 writes the policy with inclusive bounds while
  eq. 4.4 writes strict ones, and ``F(upper) − F(lower)`` literally is ``P(lower < Q ≤ upper)``,
  neither of the two. We follow eq. 4.2, the definition of the policy: both bounds are
  inclusive, ``P(lower ≤ Q ≤ upper) = F(upper) − F(lower⁻)`` where ``F(lower⁻) = P(Q < lower)``.
  A sample lying exactly on a bound satisfies the policy. A missing bound is open:
  ``lower=None`` gives ``F(upper)``, ``upper=None`` gives ``1 − F(lower⁻)``, neither gives 1.
- :class:`Distribution` is a discrete probability mass function (the empirical pmf of a window,
  or the result of a convolution); :func:`convolve` is eq. 4.5, the distribution of the *sum* of
  two independent measures, ``(f * f')(t) = Σ_x f(x) f'(t − x)``, the discrete form of the
  integral. A policy is evaluated on a distribution just as on a window. A service's
  ``<CombinedMeasure>`` names the measures :func:`combined_distribution` sums (D72).
- :class:`PolicyEvaluator` says whether a policy (or a client's requirement) is met: ``None``
  when there is no sample yet (unknown), otherwise ``P(within) ≥ probability``.

Non-finite samples: NaN is ignored by :class:`MeasureWindow`; ±inf are kept (an infinite deadline
is a valid, very late sample).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

DEFAULT_WINDOW = 50
"""Window of a requirement, which has none of its own (the Policy default of resources.xsd)."""


class QualityBounds(Protocol):
    """What a ``<Policy>`` and a client's ``<Require>`` have in common: bounds and a least probability (eq. 4.2)."""

    @property
    def measure(self) -> str:
        """Name of the quality measure bounded."""

    @property
    def lower(self) -> float | None:
        """Lower bound (eq. 4.2), None for none."""

    @property
    def upper(self) -> float | None:
        """Upper bound (eq. 4.2), None for none."""

    @property
    def probability(self) -> float:
        """Least probability with which the measure must lie within the bounds."""


def _array(samples: Iterable[float]) -> FloatArray:
    values = np.asarray(list(samples) if not isinstance(samples, np.ndarray) else samples, dtype=np.float64)
    if values.size == 0:
        raise ValueError("no samples: the empirical distribution of an empty window is undefined")
    return values


def empirical_cdf(samples: Iterable[float], x: float) -> float:
    """Eq. 4.3: ``F(x) = P(Q ≤ x) = #{Q_i ≤ x} / n`` over the samples (each weighs ``1/n``)."""
    values = _array(samples)
    return float(np.count_nonzero(values <= x)) / values.size


def probability_within(samples: Iterable[float], lower: float | None, upper: float | None) -> float:
    """Eq. 4.4 with the inclusive bounds of eq. 4.2: ``P(lower ≤ Q ≤ upper)``; a None bound is open."""
    values = _array(samples)
    inside = np.ones(values.size, dtype=bool)
    if lower is not None:
        inside &= values >= lower
    if upper is not None:
        inside &= values <= upper
    return float(np.count_nonzero(inside)) / values.size


class MeasureWindow:
    """The last ``window`` samples of one quality measure (the sliding window of eq. 4.1)."""

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        if window < 1:
            raise ValueError(f"a window holds at least one sample, not {window}")
        self._samples: deque[float] = deque(maxlen=window)
        self.pushed = 0
        """Samples pushed since the window was made (a mark to count the samples after an instant)."""

    @property
    def window(self) -> int:
        """How many samples the window keeps."""
        return self._samples.maxlen or 0

    def push(self, value: float) -> None:
        """Add a sample, dropping the oldest when the window is full; NaN is ignored."""
        value = float(value)
        if not math.isnan(value):
            self._samples.append(value)
            self.pushed += 1

    def extend(self, values: Iterable[float]) -> None:
        """Push several samples, oldest first."""
        for value in values:
            self.push(value)

    def clear(self) -> None:
        """Forget every sample (after a scenario change the old ones say nothing)."""
        self._samples.clear()

    def last(self, count: int | None = None) -> FloatArray:
        """The newest ``count`` samples (all of them when None), oldest first."""
        values = np.fromiter(self._samples, dtype=np.float64, count=len(self._samples))
        return values if count is None or count >= values.size else values[values.size - count :]

    def __len__(self) -> int:
        return len(self._samples)


@dataclass(frozen=True)
class Distribution:
    """A discrete distribution: sorted distinct ``values`` with their ``probabilities`` (sum 1)."""

    values: FloatArray
    probabilities: FloatArray

    @classmethod
    def from_samples(cls, samples: Iterable[float]) -> Distribution:
        """The empirical pmf of a window: each distinct value weighs its share of the samples."""
        values, counts = np.unique(_array(samples), return_counts=True)
        return cls(values.astype(np.float64), counts.astype(np.float64) / counts.sum())

    @classmethod
    def from_pmf(cls, pmf: dict[float, float]) -> Distribution:
        """From ``{value: probability}``; the probabilities are normalised to sum 1."""
        if not pmf:
            raise ValueError("an empty pmf is no distribution")
        values = np.array(sorted(pmf), dtype=np.float64)
        weights = np.array([pmf[v] for v in sorted(pmf)], dtype=np.float64)
        if np.any(weights < 0) or weights.sum() <= 0:
            raise ValueError("pmf weights must be non-negative with a positive sum")
        return cls(values, weights / weights.sum())

    def cdf(self, x: float) -> float:
        """Eq. 4.3 on the pmf: ``F(x) = Σ_{v ≤ x} p(v)``."""
        return float(self.probabilities[self.values <= x].sum())

    def probability_within(self, lower: float | None, upper: float | None) -> float:
        """Eq. 4.4 on the pmf, bounds inclusive (eq. 4.2) and open when None."""
        inside = np.ones(self.values.size, dtype=bool)
        if lower is not None:
            inside &= self.values >= lower
        if upper is not None:
            inside &= self.values <= upper
        return min(1.0, float(self.probabilities[inside].sum()))

    def quantile(self, q: float) -> float:
        """The smallest value ``v`` with ``F(v) ≥ q`` (inverse of the CDF)."""
        cumulative = np.cumsum(self.probabilities)
        index = int(np.searchsorted(cumulative, min(max(q, 0.0), 1.0) - 1e-12, side="left"))
        return float(self.values[min(index, self.values.size - 1)])

    def mean(self) -> float:
        """Expected value of the distribution."""
        return float(np.dot(self.values, self.probabilities))

    def pmf(self) -> dict[float, float]:
        """The distribution as {value: probability}."""
        return {float(v): float(p) for v, p in zip(self.values, self.probabilities, strict=True)}

    def __add__(self, other: Distribution) -> Distribution:
        return convolve(self, other)


def convolve(first: Distribution, second: Distribution, resolution: float | None = None) -> Distribution:
    """Eq. 4.5: the distribution of ``Q + Q'`` for independent ``Q ~ first``, ``Q' ~ second``.

    The discrete convolution ``p(t) = Σ_x f(x) f'(t − x)``: every pair of support points adds its
    values and multiplies its probabilities, equal sums are merged. Sums are rounded to 12
    decimals before merging so that float error (``0.1 + 0.2``) does not split a value; with a
    ``resolution`` they are snapped to multiples of it instead (a histogram convolution, which
    keeps the support of long convolution chains small).
    """
    sums = np.add.outer(first.values, second.values).ravel()
    weights = np.multiply.outer(first.probabilities, second.probabilities).ravel()
    if resolution is not None:
        if resolution <= 0:
            raise ValueError("resolution must be positive")
        sums = np.round(sums / resolution) * resolution
    sums = np.round(sums, 12)
    values, inverse = np.unique(sums, return_inverse=True)
    merged = np.zeros(values.size, dtype=np.float64)
    np.add.at(merged, inverse.ravel(), weights)
    return Distribution(values.astype(np.float64), merged / merged.sum())


def combined_distribution(windows: Sequence[Iterable[float]], resolution: float | None = None) -> Distribution:
    """The distribution of the sum of several independent measures (eq. 4.5 applied in turn)."""
    if not windows:
        raise ValueError("a combined measure needs at least one component")
    result = Distribution.from_samples(windows[0])
    for samples in windows[1:]:
        result = convolve(result, Distribution.from_samples(samples), resolution)
    return result


@dataclass(frozen=True)
class PolicyResult:
    """One evaluation of a policy (eq. 4.2): ``met`` is None when there were no samples (unknown).

    ``margin`` is how far, in units of the bounds' scale, the distribution's quantile at the
    required probability lies inside the bounds (negative: outside). It is ≥ 0 when the policy
    holds for one-sided bounds. The TCM uses it to pick the least bad scenario and as a learning
    feature; it takes no part in whether the policy is met.
    """

    measure: str
    probability: float | None
    required: float
    met: bool | None
    margin: float | None


def bounds_scale(lower: float | None, upper: float | None) -> float:
    """The unit of the margins and of the hysteresis band: the width, or the bound's magnitude."""
    if lower is not None and upper is not None and upper > lower:
        return upper - lower
    bound = upper if upper is not None else lower
    return abs(bound) if bound is not None and bound != 0.0 else 1.0


class PolicyEvaluator:
    """Whether one policy (eq. 4.2) holds: ``P(lower ≤ Q ≤ upper) ≥ probability`` over its window.

    Works for a Policy (its own ``window``) and for a client's requirement (``window`` given, or
    :data:`DEFAULT_WINDOW`). ``band`` (a fraction of :func:`bounds_scale`) narrows the bounds
    from both sides: the TCM's hysteresis asks more of a scenario it would switch to than of
    the one that is active.
    """

    def __init__(self, policy: QualityBounds, window: int | None = None) -> None:
        self.policy = policy
        self.window: int = window if window is not None else int(getattr(policy, "window", DEFAULT_WINDOW))
        self.scale = bounds_scale(policy.lower, policy.upper)

    @property
    def measure(self) -> str:
        """Name of the measure the policy bounds."""
        return self.policy.measure

    def bounds(self, band: float = 0.0) -> tuple[float | None, float | None]:
        """The policy's bounds narrowed by ``band`` · scale from each side (met in the middle if crossed)."""
        lower, upper = self.policy.lower, self.policy.upper
        delta = band * self.scale
        if lower is not None:
            lower += delta
        if upper is not None:
            upper -= delta
        if lower is not None and upper is not None and lower > upper:
            lower = upper = (lower + upper) / 2
        return lower, upper

    def evaluate(self, source: MeasureWindow | Iterable[float] | Distribution, band: float = 0.0) -> PolicyResult:
        """Evaluate on a window (its last ``window`` samples), samples, or a (combined) distribution."""
        required = self.policy.probability
        if isinstance(source, Distribution):
            distribution = source
        else:
            if isinstance(source, MeasureWindow):
                samples = source.last(self.window)
            else:
                samples = np.asarray(list(source), dtype=np.float64)[-self.window :]
            if samples.size == 0:
                return PolicyResult(self.measure, None, required, None, None)
            distribution = Distribution.from_samples(samples)
        lower, upper = self.bounds(band)
        probability = distribution.probability_within(lower, upper)
        return PolicyResult(self.measure, probability, required, probability >= required, self._margin(distribution))

    def _margin(self, distribution: Distribution) -> float:
        lower, upper = self.policy.lower, self.policy.upper
        p = self.policy.probability
        tail = (1.0 - p) / 2 if lower is not None and upper is not None else 1.0 - p
        margins = [math.inf]
        if upper is not None:
            margins.append((upper - distribution.quantile(1.0 - tail)) / self.scale)
        if lower is not None:
            margins.append((distribution.quantile(tail) - lower) / self.scale)
        return float(np.clip(min(margins), -10.0, 10.0))

    def met(self, source: MeasureWindow | Iterable[float] | Distribution) -> bool | None:
        """True or False, or None when there is no sample yet."""
        return self.evaluate(source).met
