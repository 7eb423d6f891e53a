"""The invalid-configuration corpus and generated hostile inputs.

Every file in ``configs/invalid/`` holds one deliberate defect and must be rejected, by the
loader and by ``ckm-validate``, with exactly the lines recorded for it in
``configs/invalid/expected.json`` (``FILE:LINE:COL: XPATH: message``, FILE relative to the
repository root). Hostile inputs that would be too large to commit (a file over the size
limit, 100k-deep nesting, a million elements, a 10 MB attribute) are generated here in
``tmp_path`` and must be rejected quickly, in bounded memory, without a traceback.

"""

from __future__ import annotations

import http.server
import json
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest

import ckmconf
from ckmconf.cli import main
from ckmconf.errors import ConfigError
from ckmconf.source import Limits
from tests.conftest import REPO

INVALID = REPO / "configs" / "invalid"
EXPECTED = INVALID / "expected.json"
FILES = sorted(INVALID.glob("*.xml"))
LINE = re.compile(r"^(?P<file>[^:]+):(?P<line>[1-9]\d*):(?P<col>[1-9]\d*): (?P<xpath>/.*?): (?P<message>.+)$")
KEYS = {"file", "line", "column", "xpath", "message"}

FAST_SECONDS = 5.0  # "rejected quickly": generous for a slow CI machine, far below a hang
MAX_RSS_MIB = 400  # peak resident memory of a ckm-validate run on a hostile file (the idle baseline is ~60 MiB)

HEAD = b'<?xml version="1.0" encoding="UTF-8"?>\n'
SYSTEM_OPEN = b'<System xmlns="urn:ckm:1" version="1.0" name="hostile">\n'
SYSTEM_CLOSE = b"</System>\n"
MILLION = 1_000_000


def relative(path: Path) -> str:
    """The path as written on the command line from the repository root."""
    return path.relative_to(REPO).as_posix()


@cache
def expected() -> dict[str, list[str]]:
    data = json.loads(EXPECTED.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def expected_lines(path: Path) -> list[str]:
    return expected()[path.name]


@pytest.fixture
def at_repo(monkeypatch: pytest.MonkeyPatch) -> Path:
    """Run from the repository root, so file names in messages match expected.json."""
    monkeypatch.chdir(REPO)
    return REPO


# ---------------------------------------------------------------- the corpus itself


def test_corpus_covers_enough_defects() -> None:
    assert len(FILES) >= 40
    assert (INVALID / "sensor_unknown_channel.xml").is_file()


def test_every_file_has_an_entry_and_every_entry_a_file() -> None:
    names = {path.name for path in FILES}
    recorded = set(expected())
    assert sorted(names - recorded) == [], "files without an entry in expected.json"
    assert sorted(recorded - names) == [], "entries of expected.json without a file"


def test_expected_entries_are_problem_lines() -> None:
    for name, lines in expected().items():
        assert lines, f"{name}: every file in configs/invalid/ must be rejected"
        for line in lines:
            assert LINE.match(line), f"{name}: not FILE:LINE:COL: XPATH: message: {line!r}"


def test_sensor_unknown_channel_is_the_line_the_docs_quote() -> None:
    """README.md and docs/config-guide.md show this exact line."""
    assert expected_lines(INVALID / "sensor_unknown_channel.xml") == [
        "configs/invalid/sensor_unknown_channel.xml:14:26: "
        "/System[@name='bad']/Node[@name='base']/Sensor[@name='speed']/@channel: "
        "HWChannel 'encodr' does not exist in node 'base'; did you mean 'encoder'?"
    ]


# ---------------------------------------------------------------- each file, three ways


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_loader_lax_reports_exactly_the_expected_problems(path: Path, at_repo: Path) -> None:
    result = ckmconf.load(relative(path), strict=False)
    assert result.system is None
    assert not result.ok
    assert [str(error) for error in result.errors] == expected_lines(path)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_loader_strict_raises_the_first_problem(path: Path, at_repo: Path) -> None:
    with pytest.raises(ConfigError) as raised:
        ckmconf.load(relative(path))
    assert str(raised.value) == expected_lines(path)[0]


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_cli_subprocess_prints_the_expected_lines(path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ckmconf.cli", relative(path)], cwd=REPO, timeout=60, capture_output=True
    )
    out, err = done.stdout.decode("utf-8"), done.stderr.decode("utf-8")
    assert "Traceback" not in out + err
    assert err == ""
    assert done.returncode == 1
    assert out.splitlines() == expected_lines(path)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_cli_in_process_prints_the_expected_lines(
    path: Path, at_repo: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main([relative(path)])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    assert captured.err == ""
    assert code == 1
    assert captured.out.splitlines() == expected_lines(path)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_cli_json_lists_the_same_problems(path: Path, at_repo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--json", relative(path)]) == 1
    problems = json.loads(capsys.readouterr().out)
    assert isinstance(problems, list)
    for problem in problems:
        assert set(problem) == KEYS
        assert isinstance(problem["line"], int) and isinstance(problem["column"], int)
    lines = [f"{p['file']}:{p['line']}:{p['column']}: {p['xpath']}: {p['message']}" for p in problems]
    assert lines == expected_lines(path)


def test_cli_json_for_the_whole_corpus_at_once() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ckmconf.cli", "--json", *map(relative, FILES)],
        cwd=REPO,
        timeout=120,
        capture_output=True,
    )
    assert done.returncode == 1
    assert done.stderr == b""
    problems = json.loads(done.stdout)
    assert isinstance(problems, list)
    assert all(isinstance(p, dict) and set(p) == KEYS for p in problems)
    assert len(problems) == sum(len(expected_lines(path)) for path in FILES)


# ---------------------------------------------------------------- generated hostile inputs


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str
    seconds: float
    peak_rss_mib: float


# The child's own peak: VmHWM belongs to the process image exec() created, while ru_maxrss also
# counts the RSS the child had as a fork of this (by then large) pytest process.
_MEASURED = """\
import re, resource, sys
from ckmconf.cli import main
code = main(sys.argv[1:])
sys.stdout.flush()
try:
    with open("/proc/self/status") as status:
        peak = int(re.search(r"^VmHWM:\\s+(\\d+) kB", status.read(), re.M).group(1))
except (OSError, AttributeError):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(f"peak-rss-kib={peak}", file=sys.stderr)
sys.exit(code)
"""


def run_measured(*args: str, out_file: Path | None = None) -> Run:
    """ckm-validate in a child process, timed, with the child's own peak memory (Linux: KiB).

    A run longer than FAST_SECONDS fails the test; ``out_file`` takes the output when it may
    be huge, so the test process does not hold it.
    """
    start = time.monotonic()
    try:
        if out_file is None:
            done = subprocess.run(
                [sys.executable, "-c", _MEASURED, *args], cwd=REPO, timeout=FAST_SECONDS, capture_output=True
            )
            out = done.stdout.decode("utf-8", "replace")
        else:
            with out_file.open("wb") as sink:
                done = subprocess.run(
                    [sys.executable, "-c", _MEASURED, *args],
                    cwd=REPO,
                    timeout=FAST_SECONDS,
                    stdout=sink,
                    stderr=subprocess.PIPE,
                )
            out = ""
    except subprocess.TimeoutExpired:
        pytest.fail(f"ckm-validate {' '.join(args)} took more than {FAST_SECONDS:g} s")
    seconds = time.monotonic() - start
    err = done.stderr.decode("utf-8", "replace")
    assert "Traceback" not in out + err, err
    found = re.search(r"^peak-rss-kib=(\d+)$", err, re.M)
    assert found, err
    rest = err[: found.start()] + err[found.end() :]
    return Run(done.returncode, out, rest.strip(), seconds, int(found.group(1)) / 1024)


def assert_rejected_fast(run: Run) -> None:
    assert run.code == 1
    assert run.err == ""
    assert run.seconds < FAST_SECONDS
    assert run.peak_rss_mib < MAX_RSS_MIB, f"peak memory {run.peak_rss_mib:.0f} MiB"


def test_file_over_the_size_limit_is_refused_before_reading(tmp_path: Path) -> None:
    limit = Limits().max_bytes
    path = tmp_path / "oversized.xml"
    with path.open("wb") as handle:  # sparse: over the limit on disk, nothing written in between
        handle.write(HEAD + SYSTEM_OPEN)
        handle.truncate(limit + 1)
    baseline = run_measured(str(REPO / "configs" / "examples" / "closed_loop.xml"))
    assert baseline.code == 0
    run = run_measured(str(path))
    assert_rejected_fast(run)
    assert run.out.splitlines() == [f"{path}:1:1: /: file is {limit + 1} bytes, more than the limit of {limit} bytes"]
    # Refused from its size alone: the 64 MiB were never read into memory.
    assert run.peak_rss_mib < baseline.peak_rss_mib + 32


def test_max_bytes_option_applies_to_real_content(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "big.xml"
    body = b"".join(b'  <Node name="n%d"/>\n' % i for i in range(20_000))
    path.write_bytes(HEAD + SYSTEM_OPEN + body + SYSTEM_CLOSE)
    size = path.stat().st_size
    assert main(["--max-bytes", "100000", str(path)]) == 1
    assert capsys.readouterr().out.splitlines() == [
        f"{path}:1:1: /: file is {size} bytes, more than the limit of 100000 bytes"
    ]
    result = ckmconf.load_bytes(path.read_bytes(), "memory.xml", strict=False, limits=Limits(max_bytes=100_000))
    assert [e.message for e in result.errors] == [f"file is {size} bytes, more than the limit of 100000 bytes"]


def deep_file(tmp_path: Path, depth: int) -> Path:
    path = tmp_path / f"deep{depth}.xml"
    path.write_bytes(HEAD + SYSTEM_OPEN + b"<Node>" * depth + b"</Node>" * depth + b"\n" + SYSTEM_CLOSE)
    return path


def test_hundred_thousand_deep_nesting_is_rejected_fast(tmp_path: Path) -> None:
    path = deep_file(tmp_path, 100_000)
    run = run_measured(str(path))
    assert_rejected_fast(run)
    [line] = run.out.splitlines()
    match = LINE.match(line)
    assert match, line
    assert (match.group("file"), match.group("line"), match.group("xpath")) == (str(path), "3", "/")
    assert match.group("message").startswith("malformed XML: ")
    assert re.search(r"depth|deep|nest", match.group("message"), re.I), line


def test_hundred_thousand_deep_nesting_in_process(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = deep_file(tmp_path, 100_000)
    start = time.monotonic()
    assert main([str(path)]) == 1
    assert time.monotonic() - start < FAST_SECONDS
    captured = capsys.readouterr()
    assert len(captured.out.splitlines()) == 1
    assert "Traceback" not in captured.out + captured.err


def test_deepest_legal_nesting_is_checked_without_recursion_errors(tmp_path: Path) -> None:
    """A profile tree nested as deep as the parser allows: bound, walked and checked."""
    depth = 250
    plugins = b"".join(b'    <Plugin name="p%d" kind="k"/>\n' % i for i in range(depth))
    chain = b"".join(b'<Use plugin="p%d">' % i for i in range(depth - 1))
    tree = chain + b'<Use plugin="missing"/>' + b"</Use>" * (depth - 1)
    path = tmp_path / "deep_profile.xml"
    path.write_bytes(
        HEAD
        + SYSTEM_OPEN
        + b'  <Node name="n"/>\n  <SmartResource name="r" node="n">\n'
        + plugins
        + b'    <Profile name="deep">'
        + tree
        + b"</Profile>\n"
        + b'    <Service name="s"/>\n  </SmartResource>\n'
        + SYSTEM_CLOSE
    )
    [error] = ckmconf.load(path, strict=False).errors
    assert error.message.startswith("plugin 'missing' does not exist in SmartResource 'r' (defined: p0, p1, ")
    assert error.line == 5 + depth
    assert error.xpath.endswith("/Use" * depth + "/@plugin")


def test_include_chain_longer_than_the_file_limit(tmp_path: Path) -> None:
    count = Limits().max_files + 20
    for index in range(count):
        include = b'  <Include href="p%d.xml"/>\n' % (index + 1) if index + 1 < count else b""
        (tmp_path / f"p{index}.xml").write_bytes(
            HEAD + b'<Part xmlns="urn:ckm:1" version="1.0">\n' + include + b'  <Node name="n%d"/>\n</Part>\n' % index
        )
    run = run_measured(str(tmp_path / "p0.xml"))
    assert_rejected_fast(run)
    last = Limits().max_files - 1
    assert run.out.splitlines() == [
        f"{tmp_path / f'p{last}.xml'}:3:3: /Part/Include: more than {Limits().max_files} files included"
    ]


def test_million_elements_behind_a_doctype_are_refused_fast(tmp_path: Path) -> None:
    path = tmp_path / "doctype_million.xml"
    path.write_bytes(HEAD + b"<!DOCTYPE System>\n" + SYSTEM_OPEN + b"<Junk/>\n" * MILLION + SYSTEM_CLOSE)
    run = run_measured(str(path))
    assert_rejected_fast(run)
    assert run.out.splitlines() == [f"{path}:2:1: /: DOCTYPE declarations are not allowed (no DTDs, no entities)"]


def test_million_unknown_elements_are_rejected_fast(tmp_path: Path) -> None:
    path = tmp_path / "flat_million.xml"
    path.write_bytes(HEAD + SYSTEM_OPEN + b"<Junk/>\n" * MILLION + SYSTEM_CLOSE)
    output = tmp_path / "out.txt"
    run = run_measured(str(path), out_file=output)
    assert_rejected_fast(run)
    with output.open("rb") as lines:
        first = lines.readline().decode("utf-8")
    assert first.startswith(f"{path}:3:1: /System[@name='hostile']/Junk[1]: unexpected element 'Junk' in System")


def test_million_elements_under_a_wrong_root_are_rejected_fast(tmp_path: Path) -> None:
    path = tmp_path / "wrong_root_million.xml"
    path.write_bytes(HEAD + b'<Robot xmlns="urn:ckm:1">\n' + b"<Junk/>\n" * MILLION + b"</Robot>\n")
    run = run_measured(str(path))
    assert_rejected_fast(run)
    assert run.out.splitlines() == [f"{path}:2:1: /Robot: root element must be System or Part, not 'Robot'"]


def test_huge_attribute_value_is_not_echoed_in_full(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "huge_attribute.xml"  # 5 MB: below the parser's own 10 MB limit on one value
    path.write_bytes(
        HEAD + SYSTEM_OPEN + b'  <Node name="n" description="' + b"x" * 5_000_000 + b'"/>\n' + SYSTEM_CLOSE
    )
    assert main([str(path)]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1
    assert "/Node[@name='n']/@description: invalid description " in lines[0]
    assert len(lines[0]) < 1000


def test_value_over_the_parser_limit_is_one_plain_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "over_parser_limit.xml"
    path.write_bytes(
        HEAD + SYSTEM_OPEN + b'  <Node name="n" description="' + b"x" * 10_000_000 + b'"/>\n' + SYSTEM_CLOSE
    )
    assert main([str(path)]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    [line] = captured.out.splitlines()
    assert line.startswith(f"{path}:3:")
    assert "XML_PARSE_HUGE" not in line


# ---------------------------------------------------------------- schema location hints are never fetched


def _recording_handler(requests: list[str]) -> type[http.server.BaseHTTPRequestHandler]:
    class Recorder(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            requests.append(f"{self.command} {self.path}")
            self.send_response(404)
            self.end_headers()

        do_HEAD = do_POST = do_GET

        def log_message(self, format: str, *args: object) -> None:
            return

    return Recorder


@pytest.fixture
def schema_server() -> Iterator[tuple[str, list[str]]]:
    """A local HTTP server that records every request: the loader must never make one."""
    requests: list[str] = []
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _recording_handler(requests))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", requests
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


def test_schema_location_hints_are_ignored_and_never_fetched(
    tmp_path: Path, schema_server: tuple[str, list[str]]
) -> None:
    url, requests = schema_server
    hints = (
        b' xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
        b' xsi:schemaLocation="urn:ckm:1 ' + url.encode() + b"/ckm.xsd urn:other " + url.encode() + b'/other.xsd"'
    )
    valid = HEAD + SYSTEM_OPEN.replace(b' name="hostile"', b' name="hostile"' + hints) + b'  <Node name="n"/>\n'
    path = tmp_path / "hinted.xml"
    path.write_bytes(valid + SYSTEM_CLOSE)
    assert ckmconf.load(path, strict=False).errors == []  # the hint is harmless: the file is judged by schemas/
    other = tmp_path / "hinted_other.xml"
    other.write_bytes(
        valid.replace(b'<Node name="n"/>', b'<Node name="n"><o:X xmlns:o="urn:other"/></Node>') + SYSTEM_CLOSE
    )
    [error] = ckmconf.load(other, strict=False).errors
    assert error.message == "element 'X' is not in the CKM namespace urn:ckm:1"
    no_namespace = tmp_path / "hinted_no_namespace.xml"
    no_namespace.write_bytes(
        HEAD
        + b'<System xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="'
        + url.encode()
        + b'/any.xsd" version="1.0" name="s"/>\n'
    )
    assert ckmconf.load(no_namespace, strict=False).errors
    assert requests == []


def test_committed_schema_location_file_is_judged_by_the_local_schema(at_repo: Path) -> None:
    result = ckmconf.load("configs/invalid/hostile_schema_location_http.xml", strict=False)
    assert [e.message for e in result.errors] == [
        "unknown attribute 'debug' on Node (allowed: name, kind, host, description)"
    ]
