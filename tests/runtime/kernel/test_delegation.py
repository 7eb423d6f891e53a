"""Code delegation: a running controller moves to a node in another process; after the handover
only the taker publishes. The gaps in wall time around it are ``ckm-bench delegation``'s figures
(benchmarks/delegation.py): a shared machine stretches them, so no test asserts them."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.delegation import PERIOD, Handover, measure


def test_a_running_controller_moves_to_another_process_and_only_the_taker_publishes_after(tmp_path: Path) -> None:
    with Handover(tmp_path) as pair:
        window = pair.hand()
        assert "pid" not in pair.runtime.controllers
        after = pair.outputs[window["handed"]:]
        assert after and any(s.source != pair.transport.guid for s in after), "the taker never published"
        by_giver = window["sources"]
        first_taker = by_giver.index(False)
        assert first_taker > 0 and not any(by_giver[first_taker:]), "the giver published after the taker began"
        assert window["stamps"] == sorted(window["stamps"])  # heard in the order they were made
        assert "delegated" in [e["kind"] for e in pair.runtime.events]


@pytest.mark.parametrize(("stamps", "sources", "figures"), [
    ([0.0, 0.02, 0.04, 0.06], [True, True, False, False],
     {"max_gap_periods": 1.0, "min_gap_periods": 1.0, "overlap": 0, "taker_published": True}),
    ([0.0, 0.02, 0.07, 0.071], [True, False, True, False],  # a missed period, then two outputs in one
     {"max_gap_periods": 2.5, "min_gap_periods": 0.05, "overlap": 1, "taker_published": True}),
    ([0.0, 0.02], [True, True], {"max_gap_periods": 1.0, "min_gap_periods": 1.0, "overlap": 0,
                                 "taker_published": False}),
    ([0.0], [True], {"max_gap_periods": None, "min_gap_periods": None, "overlap": 0, "taker_published": False}),
])
def test_the_benchmark_reports_gaps_in_periods_and_giver_outputs_after_the_taker_s_first(
    stamps: list[float], sources: list[bool], figures: dict[str, object]
) -> None:
    assert PERIOD == 0.02
    assert measure({"handed": 1, "stamps": stamps, "sources": sources}) == figures
