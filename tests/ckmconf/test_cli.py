"""The ckm-validate contract of DESIGN.md."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from ckmconf.cli import main
from tests.conftest import REPO

LINE = re.compile(r"^(?P<file>[^:]+):(?P<line>\d+):(?P<col>\d+): (?P<xpath>/\S*): (?P<message>.+)$")
GOOD = REPO / "configs" / "examples" / "closed_loop.xml"


def broken(tmp_path: Path) -> Path:
    text = GOOD.read_text().replace('channel="encoder"', 'channel="encodr"').replace('safeValue="0"', 'safeValue="3"')
    path = tmp_path / "broken.xml"
    path.write_text(text)
    return path


def test_valid_file_exits_zero(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(GOOD)]) == 0
    assert capsys.readouterr().out == ""


def test_one_line_per_problem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = broken(tmp_path)
    assert main([str(GOOD), str(path)]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    for line in lines:
        match = LINE.match(line)
        assert match, line
        assert match.group("file") == str(path)
    assert lines[0].endswith("HWChannel 'encodr' does not exist in node 'motor-node'; did you mean 'encoder'?")
    assert lines[1].endswith("safeValue 3 is outside [-1, 1]")


def test_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--json", str(broken(tmp_path))]) == 1
    problems = json.loads(capsys.readouterr().out)
    assert [set(p) for p in problems] == [{"file", "line", "column", "xpath", "message"}] * 2
    assert (
        problems[1]["xpath"]
        == "/System[@name='closed-loop']/Node[@name='motor-node']/Actuator[@name='motor']/@safeValue"
    )


def test_json_when_valid(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--json", str(GOOD)]) == 0
    assert json.loads(capsys.readouterr().out) == []


def test_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--summary", str(GOOD)]) == 0
    out = capsys.readouterr().out
    assert "closed-loop" in out and "motor-node.pid" in out


def test_missing_file_is_a_located_problem_not_a_traceback(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["/nonexistent/x.xml"]) == 1
    assert capsys.readouterr().out == "/nonexistent/x.xml:1:1: /: file not found\n"


def test_max_bytes_option(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--max-bytes", "100", str(GOOD)]) == 1
    assert "more than the limit of 100 bytes" in capsys.readouterr().out


def test_console_script_runs_in_a_fresh_process(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ckmconf.cli", str(broken(tmp_path))],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert done.returncode == 1
    assert "Traceback" not in done.stderr + done.stdout
    assert len(done.stdout.splitlines()) == 2
