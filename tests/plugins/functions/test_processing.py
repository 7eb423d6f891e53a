"""The example Function plugins: wrap-angle and outlier-reject."""

from __future__ import annotations

import math

import pytest

from ckmconf.model import Param
from plugins.functions.processing import OutlierReject, WrapAngle
from runtime.kernel.adaptation import Identity
from runtime.kernel.interfaces import ParamError


def params(**values: str) -> tuple[Param, ...]:
    return tuple(Param(name=k, value=v) for k, v in values.items())


def test_wrap_angle_in_radians() -> None:
    wrap = WrapAngle()
    assert wrap(1.5 * math.pi, 0.0) == pytest.approx(-0.5 * math.pi)
    assert wrap(-math.pi, 0.0) == -math.pi
    assert wrap(math.pi, 0.0) == -math.pi  # the interval is [−π, π)
    assert wrap(0.25, 0.0) == 0.25
    assert wrap.inverse() is wrap


def test_wrap_angle_in_degrees_around_a_center() -> None:
    wrap = WrapAngle(params(period="360", center="180"))
    assert [wrap(v, 0.0) for v in (370.0, -10.0, 359.0, 360.0)] == [10.0, 350.0, 359.0, 0.0]


def test_wrap_angle_param_errors() -> None:
    accepted = r"function 'wrap-angle' takes no parameter 'turns' \(accepted: center, period\)"
    with pytest.raises(ParamError, match=accepted):
        WrapAngle(params(turns="1"))
    with pytest.raises(ParamError, match="'period' = 'full' is not a float"):
        WrapAngle(params(period="full"))
    with pytest.raises(ParamError, match=r"'period' = -1.0 must be greater than 0"):
        WrapAngle(params(period="-1"))


def test_outlier_reject_replaces_a_spike_with_the_last_accepted_value() -> None:
    reject = OutlierReject(params(sigma="3"))
    samples = [10.0, 10.1, 9.9, 10.0, 50.0, 10.05]
    assert [reject(v, 0.0) for v in samples] == [10.0, 10.1, 9.9, 10.0, 10.0, 10.05]


def test_outlier_reject_accepts_a_real_step_after_max_rejects() -> None:
    reject = OutlierReject(params(maxRejects="3"))
    out = [reject(v, 0.0) for v in [10.0] * 4 + [20.0] * 5]
    assert out == [10.0] * 4 + [10.0, 10.0, 10.0, 20.0, 20.0]
    reject.reset()
    assert reject(-5.0, 0.0) == -5.0
    assert isinstance(reject.inverse(), Identity)


def test_outlier_reject_param_errors() -> None:
    with pytest.raises(ParamError, match="'window' = 1 must be greater than 2"):
        OutlierReject(params(window="1"))
    with pytest.raises(ParamError, match="'sigma' = 'wide' is not a float"):
        OutlierReject(params(sigma="wide"))
