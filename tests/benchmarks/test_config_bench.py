"""The config benchmark's workload is a valid system, and its report carries the contract keys."""

from __future__ import annotations

import json

import pytest

import ckmconf
from benchmarks import config
from benchmarks.cli import main
from benchmarks.generate import system_xml


def test_generated_system_is_valid() -> None:
    system = ckmconf.load_bytes(system_xml(25).encode(), "generated.xml")
    assert len(system.nodes) == 25
    assert len(system.resources) == 3
    assert system.missions[0].name == "m"


def test_report_keys() -> None:
    result = config.run(nodes=20, repeats=1)
    assert result["nodes"] == 20
    assert {"validate_s", "load_s", "cold_load_s", "elements", "bytes"} <= set(result)
    assert all(result[k] > 0 for k in ("validate_s", "load_s"))


def test_cli_json_is_the_last_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["config", "--json"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    report = json.loads(last)
    assert report["nodes"] == 1000
    assert report["load_s"] > 0


def test_a_benchmark_with_options_lists_them_under_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:  # the benchmark's own parser prints its options and exits
        main(["mission", "--help"])
    assert stopped.value.code == 0 and "usage: ckm-bench mission" in capsys.readouterr().out
