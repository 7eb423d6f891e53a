"""Every problem a run left in its run directory, counted, for the HTML run report (:mod:`.html_report`, §7.5).

Sources (what ``ckm-run`` writes, issue G, and the mission recordings of :mod:`.recording`):

- ``*.log`` (``ckm.log``, ``sim-server.log``, a partition's ``PART/ckm.log``): ERROR and CRITICAL
  lines, grouped by logger and message with the numbers blanked (``task 3 failed`` and
  ``task 4 failed`` are one problem counted twice); WARNING lines are counted the same way apart;
- ``events*.jsonl``: node events that are problems (alarms raised, partitions crashed or given up,
  reactions unavailable, delegations refused or timed out, stale or bad commands, network peers
  lost or unlinked…), grouped by node, kind and what they name;
- ``stats*.json``: tasks that missed deadlines or failed; ``ckm-run --record``'s bag failure and
  each topic's dropped samples;
- the mission recordings: ``agent-lost``, ``error``, ``signal-dropped`` events, agents whose
  recording ends without an ``end`` event, and the lines the reader skipped.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .recording import Run

_LOG_LINE = re.compile(r"^\S+ \S+ (?P<level>ERROR|CRITICAL|WARNING) (?P<logger>\S+): (?P<message>.*)$")
_NUMBER = re.compile(r"(?<![A-Za-z_])[-+]?\d+(\.\d+)?(e[-+]?\d+)?")
_PROBLEM_EVENT = re.compile(
    r"alarm$|crash|given-up|unavailable|timeout|refused|stale|bad-|lost|unlinked|miss|fail|error"
)
_NAMED = ("alarm", "partition", "actuator", "task", "resource", "service", "peer", "topic", "action")
MAX_EXAMPLE = 300


@dataclass
class Problem:
    """One kind of problem: where it comes from, its severity, what it is, how often, an example."""

    source: str
    severity: str
    what: str
    count: int = 0
    example: str = ""


@dataclass
class Problems:
    """The problems of a run, and the warnings counted apart."""

    problems: list[Problem] = field(default_factory=list)
    warnings: list[Problem] = field(default_factory=list)

    @property
    def total(self) -> int:
        """Number of problems, counting each repeated one as often as it occurred."""
        return sum(p.count for p in self.problems)


def _group(items: list[tuple[str, str, str, str]]) -> list[Problem]:
    """(source, severity, what, example) → one Problem per (source, severity, what), in first-seen order."""
    grouped: dict[tuple[str, str, str], Problem] = {}
    for source, severity, what, example in items:
        problem = grouped.setdefault((source, severity, what), Problem(source, severity, what, 0, example))
        problem.count += 1
    return list(grouped.values())


def _files(run_dir: Path, pattern: str) -> list[Path]:
    return sorted({*run_dir.glob(pattern), *run_dir.glob(f"*/{pattern}")})


def _lines(
    run_dir: Path, pattern: str, problems: list[tuple[str, str, str, str]]
) -> Iterator[tuple[str, list[str]]]:
    """(source, lines) of each text file matching ``pattern``; a file that cannot be read is a problem."""
    for path in _files(run_dir, pattern):
        source = str(path.relative_to(run_dir))
        try:
            lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError as error:
            problems.append((source, "error", f"cannot read: {error.strerror or error}", ""))
            continue
        yield source, lines


def _logs(run_dir: Path, problems: list[tuple[str, str, str, str]], warnings: list[tuple[str, str, str, str]]) -> None:
    for source, lines in _lines(run_dir, "*.log", problems):
        for line in lines:
            match = _LOG_LINE.match(line)
            if match is None:
                continue
            what = f"{match['logger']}: {_NUMBER.sub('#', match['message'])}"
            item = (source, match["level"].lower(), what[:MAX_EXAMPLE], line[:MAX_EXAMPLE])
            (warnings if match["level"] == "WARNING" else problems).append(item)


def _events(run_dir: Path, problems: list[tuple[str, str, str, str]]) -> None:
    for source, lines in _lines(run_dir, "events*.jsonl", problems):
        for line in lines:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            kind = event.get("kind") if isinstance(event, dict) else None
            if not isinstance(kind, str) or not _PROBLEM_EVENT.search(kind):
                continue
            named = " ".join(f"{k} {event[k]}" for k in _NAMED if k in event and k != "kind")
            severity = str(event.get("severity") or ("warning" if kind.startswith("network") else "error"))
            what = f"{event.get('node') or '-'}: {kind}" + (f" ({named})" if named else "")
            problems.append((source, severity, what, line[:MAX_EXAMPLE]))


def _statistics(run_dir: Path) -> list[Problem]:
    """Tasks whose counters show failures or deadline misses (one problem each, its count the counter)."""
    found = []
    for path in _files(run_dir, "stats*.json"):
        try:
            stats = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        found += _recording(str(path.relative_to(run_dir)), stats.get("recording") if isinstance(stats, dict) else None)
        nodes = stats.get("nodes") if isinstance(stats, dict) else None
        for node in (nodes or {}).values():
            tasks = (node.get("tasks") or {}) if isinstance(node, dict) else {}
            for task, figures in tasks.items():
                if not isinstance(figures, dict):
                    continue
                for key, severity in (("failures", "error"), ("misses", "warning")):
                    count = figures.get(key)
                    if isinstance(count, int) and count > 0:
                        example = f"first failure: {figures.get('first_failure')}" if key == "failures" else ""
                        found.append(
                            Problem(str(path.relative_to(run_dir)), severity, f"task {task}: {key}", count, example)
                        )
    return found


def _recording(source: str, recording: Any) -> list[Problem]:
    """``ckm-run --record``'s statistics: a failed bag, and each topic's dropped samples."""
    if not isinstance(recording, dict):
        return []
    found = []
    if recording.get("failure"):
        found.append(
            Problem(source, "error", f"recording into {recording.get('bag')} failed", 1, str(recording["failure"]))
        )
    for topic, figures in (recording.get("topics") or {}).items():
        dropped = figures.get("dropped") if isinstance(figures, dict) else None
        if isinstance(dropped, int) and dropped > 0:
            what = f"recording: samples of {topic} dropped"
            found.append(Problem(source, "warning", what, dropped, str(figures.get("firstDrop") or "")))
    return found


def _recordings(run: Run, problems: list[tuple[str, str, str, str]]) -> None:
    for event in run.events:
        source = event.source.split(":", 1)[0]
        if event.kind == "agent-lost":
            problems.append((source, "error", f"{event.agent}: agent {event.get('lost')} lost", event.source))
        elif event.kind == "error":
            what = f"{event.agent}: mission error in {event.get('where') or '?'}: {event.get('error')}"
            problems.append((source, "error", what[:MAX_EXAMPLE], event.source))
        elif event.kind == "signal-dropped":
            what = f"{event.agent}: signal {event.get('name')} dropped ({event.get('to')} had finished)"
            problems.append((source, "warning", what, event.source))
    for name, info in run.agents.items():
        if info.end is None:
            what = f"{name}: the recording ends without an end event (crashed or killed)"
            problems.append(("recording", "error", what, f"last event at {info.last:.3f} s"))
    for note in run.notes:
        problems.append(("recording", "warning", f"recording: {_NUMBER.sub('#', note)}"[:MAX_EXAMPLE], note))


def collect(run_dir: Path, run: Run) -> Problems:
    """Every problem of the run in ``run_dir`` (whose recordings ``run`` holds), grouped and counted."""
    problems: list[tuple[str, str, str, str]] = []
    warnings: list[tuple[str, str, str, str]] = []
    _logs(run_dir, problems, warnings)
    _events(run_dir, problems)
    _recordings(run, problems)
    found = _group(problems) + _statistics(run_dir)
    order = Counter({"critical": 0, "error": 1, "warning": 2})
    found.sort(key=lambda p: order.get(p.severity, 3))
    return Problems(found, _group(warnings))
