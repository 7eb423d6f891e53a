"""The network benchmarks run end to end on small workloads (figures are not asserted: machines are noisy)."""

from __future__ import annotations

from benchmarks import netbench


def test_pubsub_between_two_processes_delivers_everything() -> None:
    figures = netbench.pubsub_one("multipeer", paced=200, total=2000)
    assert figures["received"] == figures["sent"] == 2200
    assert figures["p50_us"] > 0 and figures["p99_us"] >= figures["p50_us"]
    assert figures["msgs_per_s"] > 0


def test_discovery_links_every_pair() -> None:
    result = netbench.run_discovery(peers=4)
    assert result["peers"] == 4
    assert result["all_connected_s"] is not None and result["all_connected_s"] > 0
