"""ckm-bench delegation: its JSON and table from one real handover between two processes."""

from __future__ import annotations

import json

import pytest

from benchmarks.cli import main


def test_one_handover_gives_the_gap_figures_and_no_overlap(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["delegation", "--json", "--runs", "1"]) == 0
    out = capsys.readouterr().out
    result = json.loads(out.strip().splitlines()[-1])
    assert result["runs"] == 1 and result["period_s"] == 0.02 and len(result["handovers"]) == 1
    assert result["taker_published"] is True and result["overlap"] == 0  # order, not timing
    assert result["max_gap_periods"] >= result["min_gap_periods"] > 0
    assert "largest output gap around a handover" in out


def test_a_bad_run_count_is_refused() -> None:
    with pytest.raises(SystemExit):
        main(["delegation", "--runs", "0"])
