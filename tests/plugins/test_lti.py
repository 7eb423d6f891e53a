"""The shared plant models: exact step responses and the GPC's difference equation."""

from __future__ import annotations

import math

import pytest

from plugins.lti import PlantModel, Vector, model_from_params
from runtime.kernel.interfaces import ParamError


def second_order_step(k: float, w: float, z: float, t: float) -> float:
    """Textbook unit-step response of K·ω²/(s² + 2ζω·s + ω²)."""
    if z < 1.0:
        wd = w * math.sqrt(1.0 - z * z)
        return k * (1.0 - math.exp(-z * w * t) * (math.cos(wd * t) + z / math.sqrt(1.0 - z * z) * math.sin(wd * t)))
    if z == 1.0:
        return k * (1.0 - math.exp(-w * t) * (1.0 + w * t))
    r = math.sqrt(z * z - 1.0)
    s1, s2 = -w * (z - r), -w * (z + r)
    return k * (1.0 + (s2 * math.exp(s1 * t) - s1 * math.exp(s2 * t)) / (s1 - s2))


def test_first_order_step_is_exact_whatever_the_step() -> None:
    model = PlantModel(order=1, gain=2.0, time_constant=0.2)
    x: Vector = (0.0,)
    for _ in range(37):
        x = model.advance(x, 1.0, 0.01)
    assert x[0] == pytest.approx(2.0 * (1.0 - math.exp(-0.37 / 0.2)), abs=1e-12)
    assert model.advance((0.0,), 1.0, 0.37)[0] == pytest.approx(x[0], abs=1e-12)


@pytest.mark.parametrize("damping", [0.0, 0.2, 0.7, 1.0, 3.0])
def test_second_order_step_matches_the_analytic_response(damping: float) -> None:
    model = PlantModel(order=2, gain=1.5, natural_frequency=4.0, damping=damping)
    x: Vector = (0.0, 0.0)
    for i in range(1, 201):
        x = model.advance(x, 1.0, 0.01)
        assert x[0] == pytest.approx(second_order_step(1.5, 4.0, damping, i * 0.01), abs=1e-9)


def test_static_plant_follows_its_input() -> None:
    model = PlantModel(order=0, gain=3.0)
    assert model.advance((), 2.0, 1.0) == ()
    assert model.output((), 2.0) == 6.0


@pytest.mark.parametrize("order", [1, 2])
def test_difference_equation_reproduces_the_sampled_plant(order: int) -> None:
    model = PlantModel(order=order, gain=2.0, time_constant=0.3, natural_frequency=5.0, damping=0.4)
    a, b = model.difference_equation(0.02)
    inputs = [math.sin(0.3 * k) for k in range(60)]
    x = model.equilibrium(0.0)
    ys = []
    for u in inputs:
        ys.append(x[0])
        x = model.advance(x, u, 0.02)
    for k in range(3, 60):
        predicted = -sum(a[i] * ys[k - i] for i in range(1, len(a)))
        predicted += sum(b[i - 1] * inputs[k - i] for i in range(1, len(b) + 1))
        assert ys[k] == pytest.approx(predicted, abs=1e-12)


def build(given: dict[str, float]) -> PlantModel:
    return model_from_params(given, owner="gpc 'g'", orders=(1, 2), default_order=1)


def test_model_params_are_checked() -> None:
    assert build({"timeConstant": 0.5}).time_constant == 0.5
    with pytest.raises(ParamError, match=r"gpc 'g': parameter 'order' = 0 must be one of 1, 2"):
        build({"order": 0})
    with pytest.raises(ParamError, match="'damping' does not apply to a plant of order 1"):
        build({"damping": 0.5})
    with pytest.raises(ParamError, match=r"'timeConstant' = 0.0 must be greater than 0"):
        build({"timeConstant": 0.0})
    with pytest.raises(ParamError, match="'gain' = inf must be finite"):
        build({"gain": math.inf})
