"""Mission run recording (§7.5): an append-only, crash-tolerant event log per agent.

Every mission run writes its state entries and exits, progress, composed performance (eq. 5.1),
service qualities and signals to ``RUN_DIR/mission-AGENT.jsonl``: one JSON object per line with
the common keys ``t`` (seconds since the recorder was created, on a monotonic clock), ``agent``
and ``kind``. The kinds and their keys:

- ``start``: mission, plan, wall, real · ``end``: outcome, wall, real (``real``: the machine's own
  clock, epoch seconds, which a scaled or lock-step run clock does not move: how long the mission took
  on the wall, D248)
- ``agent-lost``: lost · ``agent-found``: found · ``agent-finished``: finished, outcome
- ``signal-dropped``: name, to (a finished agent), outcome (its) · ``error``: error, where
- ``log``: path, message, and what the behavior logged with it (``BehaviorContext.log``)
- ``enter``: path (``Top/Nested/STATE``), state, mission, behavior, nested
- ``exit``: path, state, mission, to, condition, reason (``transition`` | ``stopped``)
- ``progress``: path, progress, performance (eq. 5.1, or null), mission_progress
- ``quality``: service, client, measures, scenario · ``signal``: name, direction, value
- ``outcome``: mission, path (of the nested-mission state, ``""`` for the top), outcome

Other kinds (any lower-case ``[a-z-]+`` name) are recorded and read back too; the report ignores
what it does not know, so the format can grow without breaking old readers.

Durability: each line is a single ``write(2)`` on an ``O_APPEND`` descriptor, so once
:meth:`RunRecorder.write` returns the line is in the kernel and survives a crash (even SIGKILL)
of the writing process; ``os.fsync`` (which survives a power loss) runs at most every
``fsync_every`` seconds, on ``start``/``end`` and on close. A process killed mid-write leaves
at most one half-written last line, which :func:`read_run` skips with a note.

Several agents (processes, possibly on several machines sharing a directory) each write their
own file; :func:`read_run` merges every ``mission*.jsonl`` file of the run directory. Each file's
``start`` event anchors its monotonic ``t`` to the wall clock: an event's merged time is
``(start.wall - start.t) - min over files of (start.wall - start.t) + t``, which is
``start.wall - earliest start.wall + t`` when ``start`` is written at ``t = 0``. A file (or a
part of one, after a restart appended a second ``start``) without a ``start`` is anchored at the
earliest start, with a note.
"""

from __future__ import annotations

import json
import math
import os
import re
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

KINDS = frozenset(
    {"start", "enter", "exit", "progress", "quality", "signal", "outcome", "agent-lost", "agent-found", "end"}
    | {"agent-finished", "signal-dropped", "error", "log"}
)
_KIND = re.compile(r"[a-z][a-z-]*")
FILE_GLOB = "mission*.jsonl"


class RunError(Exception):
    """A run directory cannot be read: missing, not a directory, no mission files, no events."""


def agent_file_name(agent: str) -> str:
    """The recording file of ``agent``: ``mission-AGENT.jsonl`` with the name made file-safe."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", agent).lstrip(".") or "agent"
    return f"mission-{safe}.jsonl"


def _jsonable(value: Any) -> Any:
    """``json.dumps`` fallback: numpy scalars and arrays, paths, sets; anything else as text."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, set | frozenset):
        return sorted(value, key=str)
    return str(value)


def _finite(value: Any) -> Any:
    """Replace NaN/±inf (not JSON) by null, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


class RunRecorder:
    """Append-only JSON-lines recorder of one agent's mission run (§7.5); thread-safe, a context manager.

    The file is opened on the first :meth:`write` (no I/O in the constructor); ``t`` counts from
    construction. ``start`` and ``end`` events get ``wall`` (epoch seconds) when not given.
    """

    def __init__(
        self,
        run_dir: Path,
        agent: str,
        *,
        clock: Callable[[], float] = time.monotonic,
        wall_clock: Callable[[], float] = time.time,
        fsync_every: float = 0.5,
    ) -> None:
        self.run_dir = Path(run_dir)
        self.agent = agent
        self.path = self.run_dir / agent_file_name(agent)
        self._clock = clock
        self._wall = wall_clock
        self._fsync_every = fsync_every
        self._t0 = clock()
        self._lock = threading.Lock()
        self._fd: int | None = None
        self._closed = False
        self._last_sync = 0.0
        self._dirty = False
        self.dropped = 0
        """Events written after :meth:`close` (a late signal, a thread still finishing): counted, not kept."""

    def elapsed(self) -> float:
        """Seconds since the recorder was created (the ``t`` the next event would get)."""
        return self._clock() - self._t0

    def write(self, kind: str, **fields: Any) -> bool:
        """Append one event ``{"t", "agent", "kind", **fields}`` as one line; False if dropped.

        A write after :meth:`close` is dropped and counted in :attr:`dropped`, never raised: the
        writer is often another agent's thread (a signal reaching an agent that has finished),
        and a recording that has ended must not crash it.
        """
        if not isinstance(kind, str) or not _KIND.fullmatch(kind):
            raise ValueError(f"bad event kind {kind!r} (known kinds: {', '.join(sorted(KINDS))})")
        with self._lock:
            if self._closed:
                self.dropped += 1
                return False
            if kind in ("start", "end") and "wall" not in fields:
                fields["wall"] = self._wall()
            if kind in ("start", "end") and "real" not in fields:  # the machine's clock, which no run clock moves
                fields["real"] = time.clock_gettime(time.CLOCK_REALTIME)
            event = {"t": round(self.elapsed(), 6), "agent": self.agent, "kind": kind, **fields}
            line = json.dumps(_finite(event), separators=(",", ":"), default=_jsonable, allow_nan=False) + "\n"
            fd = self._open()
            data = line.encode("utf-8")
            while data:  # a regular file takes it in one write; loop for the rare short write
                data = data[os.write(fd, data) :]
            self._dirty = True
            now = time.monotonic()  # real time: the injected clock may be frozen in tests
            if kind in ("start", "end") or now - self._last_sync >= self._fsync_every:
                os.fsync(fd)
                self._last_sync, self._dirty = now, False
        return True

    def _open(self) -> int:
        if self._fd is None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            # A crash may have left a half line: start on a fresh line so the next one stays whole.
            size = os.fstat(fd).st_size
            if size:
                with open(self.path, "rb") as existing:
                    existing.seek(size - 1)
                    if existing.read(1) != b"\n":
                        os.write(fd, b"\n")
            self._fd = fd
        return self._fd

    def close(self) -> None:
        """Sync and close the file; idempotent."""
        with self._lock:
            self._closed = True
            if self._fd is not None:
                if self._dirty:
                    os.fsync(self._fd)
                os.close(self._fd)
                self._fd = None

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


@dataclass(frozen=True)
class Event:
    """One recorded event; ``t`` is the merged run time, ``local_t`` the value in the file."""

    t: float
    agent: str
    kind: str
    fields: Mapping[str, Any]
    local_t: float
    source: str  # FILE:LINE

    def get(self, key: str, default: Any = None) -> Any:
        """The event field ``key``, ``default`` if the record has none."""
        return self.fields.get(key, default)


@dataclass
class AgentRun:
    """One agent's run: its top mission, plan, start/end (merged times) and outcome."""

    agent: str
    mission: str | None = None
    plan: str | None = None
    start: float | None = None
    end: float | None = None
    outcome: str | None = None
    first: float = 0.0  # merged time of the agent's first and last events
    last: float = 0.0

    @property
    def begin(self) -> float:
        """The start of the agent's mission time: its ``start`` event, else its first event."""
        return self.start if self.start is not None else self.first

    @property
    def finish(self) -> float:
        """The end of the agent's mission time: its ``end`` event, else its last event."""
        return self.end if self.end is not None else self.last

    @property
    def duration(self) -> float:
        """Seconds of mission time, :attr:`finish` − :attr:`begin` (never negative)."""
        return max(0.0, self.finish - self.begin)


@dataclass
class Run:
    """A recorded run: every event merged and sorted by time, the agents, notes about skipped lines."""

    run_dir: Path
    events: list[Event] = field(default_factory=list)
    agents: dict[str, AgentRun] = field(default_factory=dict)  # in order of first event
    notes: list[str] = field(default_factory=list)

    def of(self, agent: str) -> Iterator[Event]:
        """The events of one agent, in time order."""
        return (e for e in self.events if e.agent == agent)


@dataclass
class _Segment:
    """Lines of one file between two ``start`` events, with their wall anchor."""

    anchor: float | None
    lines: list[tuple[dict[str, Any], str]] = field(default_factory=list)


def _parse_file(path: Path, notes: list[str]) -> list[_Segment]:
    try:
        raw = path.read_bytes()
    except OSError as error:
        raise RunError(f"{path.name}: cannot read: {error.strerror or error}") from error
    chunks = raw.split(b"\n")
    complete = raw.endswith(b"\n") or not raw
    segments = [_Segment(None)]
    for number, chunk in enumerate(chunks, start=1):
        if not chunk.strip():
            continue
        where = f"{path.name}:{number}"
        last = number == len(chunks) and not complete
        try:
            event = json.loads(chunk.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            reason = "half-written last line (the writer stopped mid-line)" if last else "not valid JSON"
            notes.append(f"{where}: skipped: {reason}")
            continue
        problem = _check(event)
        if problem:
            notes.append(f"{where}: skipped: {problem}")
            continue
        if event["kind"] == "start":
            wall = event.get("wall")
            anchor = float(wall) - float(event["t"]) if isinstance(wall, int | float) else None
            if anchor is None:
                notes.append(f"{where}: start without a wall time; anchored at the earliest start")
            segments.append(_Segment(anchor))
        segments[-1].lines.append((event, where))
    if segments[0].lines:
        notes.append(f"{segments[0].lines[0][1]}: events before any start; anchored at the earliest start")
    return [s for s in segments if s.lines]


def _check(event: Any) -> str | None:
    if not isinstance(event, dict):
        return "not a JSON object"
    t = event.get("t")
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        return "no numeric 't'"
    if not isinstance(event.get("agent"), str):
        return "no 'agent'"
    kind = event.get("kind")
    if not isinstance(kind, str) or not _KIND.fullmatch(kind):
        return f"bad kind {kind!r}"
    return None


def read_run(run_dir: Path) -> Run:
    """Read and merge every ``mission*.jsonl`` file of ``run_dir``; raises :class:`RunError`."""
    run_dir = Path(run_dir)
    if not run_dir.exists():
        raise RunError(f"{run_dir}: no such run directory")
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: not a directory")
    try:
        files = sorted(p for p in run_dir.glob(FILE_GLOB) if p.is_file())
    except OSError as error:
        raise RunError(f"{run_dir}: cannot list: {error.strerror or error}") from error
    if not files:
        raise RunError(f"{run_dir}: no mission recording ({FILE_GLOB})")
    run = Run(run_dir)
    segments = [s for path in files for s in _parse_file(path, run.notes)]
    anchors = [s.anchor for s in segments if s.anchor is not None]
    origin = min(anchors) if anchors else 0.0
    events: list[Event] = []
    for segment in segments:
        offset = (segment.anchor - origin) if segment.anchor is not None else 0.0
        for data, where in segment.lines:
            local = float(data["t"])
            fields = {k: v for k, v in data.items() if k not in ("t", "agent", "kind")}
            events.append(Event(offset + local, data["agent"], data["kind"], fields, local, where))
    run.events = sorted(events, key=lambda e: e.t)  # stable: file order breaks ties
    if not run.events:
        raise RunError(f"{run_dir}: no readable events in {', '.join(p.name for p in files)}")
    for event in run.events:
        info = run.agents.get(event.agent)
        if info is None:
            info = run.agents[event.agent] = AgentRun(event.agent, first=event.t)
        info.last = event.t
        if event.kind == "start" and info.start is None:
            info.start = event.t
            info.mission = event.get("mission")
            info.plan = event.get("plan")
        elif event.kind == "end":
            info.end = event.t
            info.outcome = event.get("outcome")
    return run
