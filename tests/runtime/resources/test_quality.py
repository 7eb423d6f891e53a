"""Quality measures and policies: eq. 4.3 (CDF), 4.4 (probability within bounds), 4.5 (convolution)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ckmconf.model.missions import Require
from ckmconf.model.resources import Policy
from runtime.resources.quality import (
    DEFAULT_WINDOW,
    Distribution,
    MeasureWindow,
    PolicyEvaluator,
    combined_distribution,
    convolve,
    empirical_cdf,
    probability_within,
)

SAMPLES = [3.0, 1.0, 2.0, 2.0]  # sorted: 1, 2, 2, 3 — a tie at 2


@pytest.mark.parametrize(
    ("x", "expected"),
    [(0.0, 0.0), (1.0, 0.25), (1.5, 0.25), (1.999, 0.25), (2.0, 0.75), (2.5, 0.75), (3.0, 1.0), (9.0, 1.0)],
)
def test_empirical_cdf_counts_samples_at_or_below(x: float, expected: float) -> None:
    assert empirical_cdf(SAMPLES, x) == expected


def test_empirical_cdf_of_nothing_is_undefined() -> None:
    with pytest.raises(ValueError):
        empirical_cdf([], 1.0)
    with pytest.raises(ValueError):
        probability_within([], None, 1.0)


@pytest.mark.parametrize(
    ("lower", "upper", "expected"),
    [
        (2.0, 3.0, 3 / 5),  # inclusive both ends: 2, 2, 3
        (2.0, 2.0, 2 / 5),  # a degenerate interval holds the tie
        (None, 2.0, 3 / 5),  # open below: F(2)
        (3.0, None, 2 / 5),  # open above: 1 − F(3⁻)
        (None, None, 1.0),
        (2.5, 2.9, 0.0),
        (0.0, 10.0, 1.0),
    ],
)
def test_probability_within_inclusive_and_open_bounds(
    lower: float | None, upper: float | None, expected: float
) -> None:
    samples = [1.0, 2.0, 2.0, 3.0, 4.0]
    assert probability_within(samples, lower, upper) == pytest.approx(expected)


def test_probability_within_is_f_upper_minus_f_lower_left_limit() -> None:
    samples = [1.0, 2.0, 2.0, 3.0, 4.0]
    below_lower = sum(1 for s in samples if s < 2.0) / len(samples)  # F(2⁻)
    assert probability_within(samples, 2.0, 3.0) == pytest.approx(empirical_cdf(samples, 3.0) - below_lower)
    # The literal eq. 4.4, F(upper) − F(lower), would drop the samples lying on the lower bound.
    assert empirical_cdf(samples, 3.0) - empirical_cdf(samples, 2.0) == pytest.approx(1 / 5)


def test_measure_window_slides_and_ignores_nan() -> None:
    window = MeasureWindow(3)
    window.extend([1.0, 2.0, float("nan"), 3.0, 4.0])
    assert len(window) == 3 and window.window == 3
    assert window.last().tolist() == [2.0, 3.0, 4.0]
    assert window.last(2).tolist() == [3.0, 4.0]
    assert window.last(10).tolist() == [2.0, 3.0, 4.0]
    window.push(math.inf)  # a lost message: infinitely late, kept
    assert window.last().tolist() == [3.0, 4.0, math.inf]
    window.clear()
    assert len(window) == 0
    with pytest.raises(ValueError):
        MeasureWindow(0)


def test_distribution_from_samples_matches_the_sample_functions() -> None:
    dist = Distribution.from_samples(SAMPLES)
    assert dist.pmf() == {1.0: 0.25, 2.0: 0.5, 3.0: 0.25}
    rng = np.random.default_rng(7)
    samples = rng.integers(0, 6, size=40).astype(float).tolist()
    dist = Distribution.from_samples(samples)
    for x in [-1.0, 0.0, 2.0, 2.5, 5.0]:
        assert dist.cdf(x) == pytest.approx(empirical_cdf(samples, x))
    for lower, upper in [(1.0, 3.0), (None, 2.0), (4.0, None), (2.0, 2.0)]:
        assert dist.probability_within(lower, upper) == pytest.approx(probability_within(samples, lower, upper))


def test_distribution_quantile_inverts_the_cdf() -> None:
    dist = Distribution.from_samples(SAMPLES)
    assert dist.quantile(0.0) == 1.0
    assert dist.quantile(0.25) == 1.0
    assert dist.quantile(0.5) == 2.0
    assert dist.quantile(0.75) == 2.0
    assert dist.quantile(0.76) == 3.0
    assert dist.quantile(1.0) == 3.0
    assert dist.mean() == pytest.approx(2.0)


def test_convolution_of_two_small_distributions() -> None:
    first = Distribution.from_pmf({1.0: 0.5, 2.0: 0.5})
    second = Distribution.from_pmf({0.0: 0.25, 1.0: 0.75})
    total = convolve(first, second)
    # 1 = 1+0: .5·.25; 2 = 1+1 or 2+0: .5·.75 + .5·.25; 3 = 2+1: .5·.75
    assert total.pmf() == pytest.approx({1.0: 0.125, 2.0: 0.5, 3.0: 0.375})
    assert (first + second).pmf() == pytest.approx(total.pmf())
    # The same from samples: the empirical pmfs of [1, 2] and [0, 1, 1, 1].
    combined = combined_distribution([[1.0, 2.0], [0.0, 1.0, 1.0, 1.0]])
    assert combined.pmf() == pytest.approx(total.pmf())
    assert combined.probability_within(None, 2.0) == pytest.approx(0.625)
    assert combined.probability_within(2.0, 3.0) == pytest.approx(0.875)


def test_convolution_of_two_dice() -> None:
    die = Distribution.from_pmf({float(v): 1.0 for v in range(1, 7)})
    total = die + die
    assert total.values.tolist() == [float(v) for v in range(2, 13)]
    assert total.pmf()[7.0] == pytest.approx(6 / 36)
    assert total.pmf()[2.0] == pytest.approx(1 / 36)
    assert total.cdf(4.0) == pytest.approx(6 / 36)
    assert total.mean() == pytest.approx(7.0)
    three = combined_distribution([[1, 2, 3, 4, 5, 6]] * 3)
    assert three.pmf()[10.0] == pytest.approx(27 / 216)


def test_convolution_merges_float_noise_and_snaps_to_a_resolution() -> None:
    total = convolve(Distribution.from_pmf({0.1: 1.0}), Distribution.from_pmf({0.2: 1.0}))
    assert total.values.size == 1 and total.values[0] == pytest.approx(0.3)
    first = Distribution.from_pmf({0.011: 0.5, 0.013: 0.5})
    second = Distribution.from_pmf({0.004: 0.5, 0.006: 0.5})
    exact = convolve(first, second)
    assert exact.pmf() == pytest.approx({0.015: 0.25, 0.017: 0.5, 0.019: 0.25})
    binned = convolve(first, second, resolution=0.005)  # 0.017 → 0.015, 0.019 → 0.02
    assert binned.values.tolist() == pytest.approx([0.015, 0.02])
    assert binned.probabilities.tolist() == pytest.approx([0.75, 0.25])
    with pytest.raises(ValueError):
        convolve(first, second, resolution=0.0)


def test_policy_evaluator_uses_its_window_and_inclusive_bounds() -> None:
    policy = Policy(measure="deadline", upper=0.012, probability=0.75, window=4)
    evaluator = PolicyEvaluator(policy)
    window = MeasureWindow(10)
    window.extend([0.050, 0.010, 0.012, 0.013, 0.009])  # the last 4: 0.010, 0.012 (on the bound), 0.013, 0.009
    result = evaluator.evaluate(window)
    assert result.probability == pytest.approx(0.75) and result.met is True
    strict = PolicyEvaluator(Policy(measure="deadline", upper=0.012, probability=0.8, window=4))
    assert strict.met(window) is False
    assert strict.met([0.010, 0.011]) is True  # plain samples work too
    assert evaluator.evaluate(MeasureWindow(5)).met is None  # no sample: unknown
    assert evaluator.evaluate(MeasureWindow(5)).probability is None


def test_policy_evaluator_margin_and_band() -> None:
    policy = Policy(measure="m", upper=3.0, probability=0.75, window=10)
    result = PolicyEvaluator(policy).evaluate([1.0, 2.0, 3.0, 4.0])
    assert result.met is True and result.margin == pytest.approx(0.0)  # the 0.75-quantile sits on the bound
    below = PolicyEvaluator(Policy(measure="m", upper=2.5, probability=0.75)).evaluate([1.0, 2.0, 3.0, 4.0])
    assert below.met is False and below.margin == pytest.approx((2.5 - 3.0) / 2.5)
    two_sided = PolicyEvaluator(Policy(measure="m", lower=1.0, upper=3.0))
    assert two_sided.bounds(0.1) == pytest.approx((1.2, 2.8))  # narrowed by 10 % of the width
    lower, upper = PolicyEvaluator(Policy(measure="m", upper=0.012)).bounds(0.05)
    assert lower is None and upper == pytest.approx(0.0114)
    assert PolicyEvaluator(Policy(measure="m", lower=2.0, upper=2.0)).bounds(0.5) == (2.0, 2.0)


def test_policy_evaluator_takes_requirements_and_distributions() -> None:
    requirement = Require(measure="reliability", lower=0.8, probability=0.9)
    evaluator = PolicyEvaluator(requirement)
    assert evaluator.window == DEFAULT_WINDOW
    assert evaluator.met([0.9] * 9 + [0.5]) is True
    assert evaluator.met([0.9] * 8 + [0.5] * 2) is False
    # A combined measure: processing + transport, from their empirical pmfs (eq. 4.5).
    total = combined_distribution([[0.005, 0.010], [0.005, 0.010]])  # 0.01: .25, 0.015: .5, 0.02: .25
    on_sum = PolicyEvaluator(Policy(measure="total", upper=0.015, probability=0.75))
    assert on_sum.evaluate(total).probability == pytest.approx(0.75)
    assert on_sum.met(total) is True
    assert PolicyEvaluator(Policy(measure="total", upper=0.015, probability=0.8)).met(total) is False
