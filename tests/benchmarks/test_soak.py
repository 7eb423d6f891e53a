"""ckm-bench soak: the loopback system has the use case's shape and rates, and a short soak reports its figures."""

from __future__ import annotations

from pathlib import Path

import ckmconf
from benchmarks.soak import USE_CASE, run, system_xml
from runtime.verification.verify import verify_safely


def test_the_soak_system_has_the_use_cases_node_shapes_and_rates(tmp_path: Path) -> None:
    text, names = system_xml()
    path = tmp_path / "soak.xml"
    path.write_text(text)
    soak = ckmconf.load(path)
    assert verify_safely(soak) == []
    lab = {n.name: n for n in ckmconf.load(USE_CASE).nodes if n.sensors}
    assert names == list(lab)
    for node in soak.nodes:
        original = lab[node.name]
        assert sorted(s.period for s in node.sensors) == sorted(s.period for s in original.sensors)
        assert sorted(c.period for c in node.controllers) == sorted(c.period for c in original.controllers)
        assert len(node.actuators) == len(original.actuators)
        assert node.monitor is not None and original.monitor is not None
        assert node.monitor.period == original.monitor.period


def test_a_short_soak_reports_memory_and_clean_exits() -> None:
    result = run(["--minutes", "0.25", "--warmup", "5"])
    assert set(result) >= {"minutes", "nodes", "rss_start_mb", "rss_end_mb", "rss_peak_mb"}
    assert result["nodes"] == ["kobuki", "turtlebot", "nao"]
    assert 0 < result["rss_start_mb"] <= result["rss_peak_mb"] and result["rss_end_mb"] <= result["rss_peak_mb"]
    assert result["exit_codes"] == {"kobuki": 0, "turtlebot": 0, "nao": 0}
