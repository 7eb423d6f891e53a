"""Adaptation functions against hand-computed values; chains, inverse chains and their errors."""

from __future__ import annotations

import math
from collections.abc import Sequence

import pytest

from ckmconf.errors import ConfigError, Loc
from ckmconf.loader import load
from ckmconf.model import Param
from ckmconf.model import adaptation as model
from plugins.functions.processing import OutlierReject, WrapAngle
from runtime.kernel import adaptation as ad
from runtime.kernel.interfaces import AdaptationFunction
from runtime.registry import Registry
from tests.conftest import CONFIGS


def run(function: AdaptationFunction, values: Sequence[float], dt: float = 0.1) -> list[float]:
    return [function(v, i * dt) for i, v in enumerate(values)]


@pytest.fixture
def registry() -> Registry:
    reg = Registry(load_entry_points=False)
    reg.register("function", "wrap-angle", WrapAngle)
    reg.register("function", "outlier-reject", OutlierReject)
    return reg


# ---------------------------------------------------------------- the functions, by hand


def test_linear_and_its_inverse() -> None:
    f = ad.Linear(2.0, 1.0)
    assert f(3.0, 0.0) == 7.0
    assert f.inverse()(7.0, 0.0) == 3.0
    with pytest.raises(ad.NotInvertibleError, match="gain 0"):
        ad.Linear(0.0, 1.0).inverse()


def test_polynomial() -> None:
    assert ad.Polynomial([1.0, 2.0, 3.0])(2.0, 0.0) == 17.0  # 1 + 2·2 + 3·4
    assert ad.Polynomial([0.5, 4.0, 0.0]).inverse()(8.5, 0.0) == 2.0  # trailing zero: degree 1
    with pytest.raises(ad.NotInvertibleError, match="degree 2"):
        ad.Polynomial([1.0, 2.0, 3.0]).inverse()
    with pytest.raises(ad.NotInvertibleError, match="degree 0"):
        ad.Polynomial([4.0]).inverse()


def test_low_pass_is_first_order_and_time_aware() -> None:
    f = ad.LowPass(1.0)
    assert f(0.0, 10.0) == 0.0  # the first sample passes
    assert f(1.0, 10.1) == pytest.approx(1.0 - math.exp(-2.0 * math.pi * 0.1))
    assert f(1.0, 10.1) == pytest.approx(1.0 - math.exp(-2.0 * math.pi * 0.1))  # no time, no change
    g = ad.LowPass(1.0)
    g(0.0, 0.0)
    g(1.0, 0.05)
    assert g(1.0, 0.1) == pytest.approx(f(1.0, 10.1))  # two half periods = one period
    f.reset()
    assert f(5.0, 11.0) == 5.0
    assert isinstance(f.inverse(), ad.Identity)
    with pytest.raises(ValueError, match="cutoff"):
        ad.LowPass(0.0)


def test_moving_average_and_median() -> None:
    assert run(ad.MovingAverage(3), [1.0, 2.0, 3.0, 4.0]) == [1.0, 1.5, 2.0, 3.0]
    assert run(ad.Median(3), [1.0, 100.0, 2.0, 3.0, 4.0]) == [1.0, 50.5, 2.0, 3.0, 3.0]
    median = ad.Median(3)
    run(median, [7.0, 7.0])
    median.reset()
    assert median(1.0, 0.0) == 1.0


def test_clamp_and_deadband() -> None:
    assert run(ad.Clamp(-1.0, 1.0), [-2.0, 0.5, 3.0]) == [-1.0, 0.5, 1.0]
    assert run(ad.Deadband(0.5), [0.5, -0.4, 0.6, -2.0]) == [0.0, 0.0, 0.6, -2.0]
    with pytest.raises(ValueError, match="above max"):
        ad.Clamp(2.0, 1.0)


def test_lookup_interpolates_and_holds_the_ends() -> None:
    f = ad.Lookup([(0.0, 0.0), (1.0, 10.0), (3.0, 20.0)])
    assert run(f, [-1.0, 0.5, 1.0, 2.0, 5.0]) == [0.0, 5.0, 10.0, 15.0, 20.0]
    assert run(f.inverse(), [-5.0, 5.0, 15.0, 25.0]) == [0.0, 0.5, 2.0, 3.0]
    falling = ad.Lookup([(0.0, 10.0), (2.0, 0.0)])
    assert falling.inverse()(2.5, 0.0) == 1.5
    with pytest.raises(ad.NotInvertibleError, match="monotonic"):
        ad.Lookup([(0.0, 0.0), (1.0, 1.0), (2.0, 0.0)]).inverse()
    with pytest.raises(ValueError, match="increase strictly"):
        ad.Lookup([(0.0, 0.0), (0.0, 1.0)])


# ---------------------------------------------------------------- chains


def at(line: int) -> Loc:
    return Loc("test.xml", line, 3, f"/Adaptation/Step{line}")


def test_no_adaptation_is_the_identity(registry: Registry) -> None:
    assert ad.build_chain(None, registry, inverse=False)(4.2, 0.0) == 4.2
    assert ad.build_chain(None, registry, inverse=True)(4.2, 0.0) == 4.2


def test_example_sensor_chain_by_hand(registry: Registry) -> None:
    sensor = load(CONFIGS / "examples" / "adaptation_chain.xml").nodes[0].sensors[0]
    chain = ad.build_chain(sensor.adaptation, registry, inverse=False)
    # 1.8 V → 1800 mV → table 25 + 95·0.5 = 72.5 °C → 0.4 + 0.998·72.5 + 1e-5·72.5² (filters pass a first sample)
    assert chain(1.8, 0.0) == pytest.approx(0.4 + 0.998 * 72.5 + 1e-5 * 72.5**2)


def test_example_actuator_chain_runs_in_document_order(registry: Registry) -> None:
    actuator = load(CONFIGS / "examples" / "adaptation_chain.xml").nodes[0].actuators[0]
    chain = ad.build_chain(actuator.adaptation, registry, inverse=False)
    assert chain(750.0, 0.0) == pytest.approx(750.0 * 0.000667)  # watts → duty
    assert chain(10.0, 0.0) == 0.0  # inside the dead band
    assert chain(2000.0, 0.0) == 1.0  # clamped in duty units


INVERTIBLE = model.Adaptation(
    steps=(
        model.Linear(gain=2.0, offset=1.0),
        model.Polynomial(coefficients=(3.0, -0.5)),
        model.Lookup(points=(model.Point(x=-10.0, y=8.0), model.Point(x=0.0, y=2.0), model.Point(x=10.0, y=-1.0))),
        model.LowPass(cutoff=5.0),
        model.Clamp(min=-1.0, max=8.0),
    )
)


@pytest.mark.parametrize("x", [-3.0, -1.0, 0.0, 0.25, 2.0, 3.4])
def test_inverse_chain_round_trips(registry: Registry, x: float) -> None:
    forward = ad.build_chain(INVERTIBLE, registry, inverse=False)
    backward = ad.build_chain(INVERTIBLE, registry, inverse=True)
    assert backward(forward(x, 0.0), 0.0) == pytest.approx(x, abs=1e-12)


def test_inverse_chain_keeps_clamp_and_deadband(registry: Registry) -> None:
    adaptation = model.Adaptation(steps=(model.Linear(gain=10.0), model.Deadband(width=1.0), model.Clamp(min=0, max=5)))
    backward = ad.build_chain(adaptation, registry, inverse=True)
    assert backward(9.0, 0.0) == 0.5  # clamped to 5, then 5 / 10
    assert backward(0.5, 0.0) == 0.0  # in the dead band
    assert backward(3.0, 0.0) == pytest.approx(0.3)


def test_non_invertible_step_is_a_located_config_error(registry: Registry) -> None:
    adaptation = model.Adaptation(steps=(model.Linear(gain=2.0), model.Polynomial(coefficients=(0, 1, 1), loc=at(7))))
    assert ad.build_chain(adaptation, registry, inverse=False)(1.0, 0.0) == 6.0
    with pytest.raises(ConfigError) as caught:
        ad.build_chain(adaptation, registry, inverse=True)
    assert str(caught.value) == (
        "test.xml:7:3: /Adaptation/Step7: Polynomial of degree 2 has no inverse (only degree 1), "
        "so it cannot be in an inverse chain"
    )


def test_function_step_resolves_the_plugin_with_its_params(registry: Registry) -> None:
    step = model.Function(plugin="wrap-angle", params=(Param(name="period", value="360"),))
    chain = ad.build_chain(model.Adaptation(steps=(model.Linear(gain=2.0), step)), registry, inverse=False)
    assert chain(200.0, 0.0) == 40.0  # 400° wrapped into [−180, 180)
    assert ad.build_chain(model.Adaptation(steps=(step,)), registry, inverse=True)(190.0, 0.0) == -170.0


def test_function_errors_are_located_at_the_step(registry: Registry) -> None:
    bad = model.Function(plugin="wrap-angle", params=(Param(name="turns", value="1"),), loc=at(4))
    with pytest.raises(ConfigError, match=r"test.xml:4:3: .*wrap-angle' takes no parameter 'turns'"):
        ad.build_chain(model.Adaptation(steps=(bad,)), registry, inverse=False)
    unknown = model.Function(plugin="no-such", loc=at(5))
    with pytest.raises(ConfigError, match=r"test.xml:5:3: /Adaptation/Step5/@plugin: .*no-such"):
        ad.build_chain(model.Adaptation(steps=(unknown,)), registry, inverse=False)


class Doubler(AdaptationFunction):
    """A Function plugin that is not a Step, so it has no inverse."""

    def __init__(self, params: Sequence[Param]) -> None:
        self.params = params

    def __call__(self, value: float, now: float) -> float:
        return 2.0 * value


def test_function_without_inverse_in_an_inverse_chain(registry: Registry) -> None:
    registry.register("function", "doubler", Doubler)
    adaptation = model.Adaptation(steps=(model.Function(plugin="doubler", loc=at(9)),))
    assert ad.build_chain(adaptation, registry, inverse=False)(2.0, 0.0) == 4.0
    with pytest.raises(ConfigError, match="function plugin 'doubler' has no inverse"):
        ad.build_chain(adaptation, registry, inverse=True)


def test_chain_reset_forgets_filter_history(registry: Registry) -> None:
    chain = ad.build_chain(model.Adaptation(steps=(model.MovingAverage(window=4),)), registry, inverse=False)
    run(chain.functions[0], [10.0, 10.0])
    chain.reset()
    assert chain(2.0, 1.0) == 2.0
