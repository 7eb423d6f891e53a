"""ckm-bench rates runs end to end on a short, fast workload (figures are loosely checked: machines are noisy)."""

from __future__ import annotations

import json

import pytest

from benchmarks import rates
from benchmarks.cli import BENCHMARKS

FAST = {"Pan-Tilt Camera": 0.1, "Navigation": 0.16, "Global Recog.": 0.16}
CONTRACT = {"name", "set_rate_s", "avg_rate_s", "rate_std_s", "avg_delay_s", "delay_std_s"}
THESIS_KEYS = {"thesis_avg_rate_s", "thesis_rate_std_s", "thesis_avg_delay_s", "thesis_delay_std_s"}


@pytest.fixture(scope="module")
def result() -> dict[str, object]:
    return rates.run(duration=3.0, periods=FAST)


def test_rates_carries_the_contract_keys(result: dict[str, object]) -> None:
    services = result["services"]
    assert isinstance(services, list)
    assert [s["name"] for s in services] == list(FAST)
    for service in services:
        assert CONTRACT | THESIS_KEYS | {"samples"} <= set(service)
        assert service["thesis_avg_rate_s"] == rates.THESIS[service["name"]]["avg_rate_s"]
    json.loads(json.dumps(result))  # the CLI prints it as one JSON line


def test_every_service_delivers_at_about_its_set_rate(result: dict[str, object]) -> None:
    services = result["services"]
    assert isinstance(services, list)
    for service in services:
        period = FAST[service["name"]]
        assert service["samples"] >= 0.5 * 3.0 / period
        assert service["lost"] == 0
        assert service["avg_rate_s"] == pytest.approx(period, rel=0.25)
        assert service["rate_std_s"] >= 0
        assert -0.01 < service["avg_delay_s"] < 0.5  # offset-corrected: may dip below 0 by the offset error
        assert 0 < service["raw_avg_delay_s"] < 0.5  # one host, one clock
        assert service["delay_std_s"] >= 0


def test_rates_is_registered_and_described(result: dict[str, object]) -> None:
    assert "rates" in BENCHMARKS
    rows = rates.describe(result)
    assert any(label.startswith("Global Recog.") for label, _ in rows)


def test_unknown_services_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown services"):
        rates.run(duration=0.1, periods={"Lidar": 0.1})
