"""On-line mission evaluation (§7.5, Table 7.9, Fig. 7.21/7.23): ``ckm-mission report RUN_DIR``.

Reads a run recorded by :class:`~runtime.missions.recording.RunRecorder` and characterises each
state: how long it was active, its share of the mission and its average performance.

Definitions (see ``docs/decisions.md``):

- **Time per state**: one value per visit, ``exit.t - enter.t``. A state still active when the
  agent's recording stops counts until the agent's ``end`` event, or its last event when there
  is none (a crash). Exiting a nested-mission state also closes its still-open inner states.
- **Contribution**: visit time / the agent's mission time (its ``start`` to its ``end``, or to
  its last event). With contiguous states the contributions of an agent sum to 1.
- **Depth**: ``"leaf"`` rows are the behavior states (``enter`` with ``nested`` null) by full
  path; ``"top"`` rows are the top mission's own states, so a nested mission is one row (the
  thesis' NAVIGATION row), its time being the nested state's.
- **Avg. performance**: the time-weighted mean of the ``performance`` of the ``progress``
  events recorded while the row's state was active (for a ``"top"`` row, those of any state
  below it): each sample holds until the next one or the end of the visit; null samples and
  the time before the first sample of a visit do not count. When every sample has zero weight
  (e.g. one sample at the exit instant) the plain mean is used.
- **Progress at end**: the ``progress`` of the last such sample.

The table prints contributions in percent (Table 7.9's header says % but shows fractions);
``--json`` carries them as fractions.
"""

from __future__ import annotations

import json as jsonlib
import sys
from bisect import bisect_left, bisect_right
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from .recording import Event, Run, RunError, agent_file_name, read_run

Depth = Literal["leaf", "top"]


@dataclass
class StateRow:
    """One row of Table 7.9: a state of one agent and its visits."""

    agent: str
    path: str
    state: str
    visits: list[float] = field(default_factory=list)  # seconds per visit
    contribution: list[float] = field(default_factory=list)  # share of the agent's mission time per visit
    performance: float | None = None
    progress_end: float | None = None
    spans: list[tuple[float, float]] = field(default_factory=list)  # (enter, exit) run times per visit

    @property
    def label(self) -> str:
        """The path without the top mission's name (``Navigation/NAV``)."""
        return self.path.split("/", 1)[1] if "/" in self.path else self.path

    @property
    def time(self) -> float:
        """Total seconds the state was active, over all its visits."""
        return sum(self.visits)

    def to_json(self) -> dict[str, Any]:
        """The row as JSON-ready values, rounded to the recording's microsecond resolution."""
        return {  # rounded to the recording's microsecond resolution
            "path": self.path,
            "state": self.state,
            "visits_s": [round(v, 6) for v in self.visits],
            "time_s": round(self.time, 6),
            "contribution": [round(c, 6) for c in self.contribution],
            "performance": None if self.performance is None else round(self.performance, 6),
            "progress_end": self.progress_end,
        }


@dataclass
class AgentReport:
    """One agent's rows of Table 7.9 (in order of first entry), mission time and outcome."""

    agent: str
    mission: str | None
    plan: str | None
    total: float
    outcome: str | None
    rows: list[StateRow] = field(default_factory=list)
    qualities: dict[str, dict[str, float]] = field(default_factory=dict)  # service → measure → mean

    def to_json(self) -> dict[str, Any]:
        """The agent's report (mission, plan, total time, outcome, state rows, qualities) as JSON."""
        return {
            "agent": self.agent,
            "mission": self.mission,
            "plan": self.plan,
            "total_s": round(self.total, 6),
            "outcome": self.outcome,
            "rows": [r.to_json() for r in self.rows],
            "qualities": self.qualities,
        }


@dataclass
class Report:
    """Evaluation of a whole run (Table 7.9) at ``depth`` leaf or top: one :class:`AgentReport` per agent, and notes."""

    depth: str
    agents: list[AgentReport] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def rows(self) -> list[StateRow]:
        """Every agent's state rows, in agent order."""
        return [row for agent in self.agents for row in agent.rows]

    def to_json(self) -> dict[str, Any]:
        """The report as JSON-ready values (what ``ckm-mission report --json`` prints)."""
        return {"depth": self.depth, "agents": [a.to_json() for a in self.agents], "notes": self.notes}


def _spans(
    events: list[Event], finish: float, notes: list[str]
) -> tuple[dict[str, list[tuple[float, float]]], dict[str, Event]]:
    """Visits (enter, exit) per path, and the ``enter`` event of each path's first visit."""
    spans: dict[str, list[tuple[float, float]]] = defaultdict(list)
    entered: dict[str, Event] = {}
    open_: dict[str, float] = {}
    for event in events:
        path = event.get("path")
        if event.kind not in ("enter", "exit"):
            continue
        if not isinstance(path, str) or not path:
            notes.append(f"{event.source}: {event.kind} without a path; ignored")
            continue
        if event.kind == "enter":
            if path in open_:
                notes.append(f"{event.source}: {path} entered again before its exit; previous visit closed here")
                spans[path].append((open_.pop(path), event.t))
            open_[path] = event.t
            entered.setdefault(path, event)
        elif path not in open_:
            notes.append(f"{event.source}: exit of {path} without an enter; ignored")
        else:
            for inner in [p for p in open_ if p == path or p.startswith(path + "/")]:
                spans[inner].append((open_.pop(inner), event.t))
    for path, begin in open_.items():  # still active when the recording stops
        spans[path].append((begin, max(begin, finish)))
    return spans, entered


def _is_row(path: str, enter: Event, depth: str) -> bool:
    if depth == "top":
        return path.count("/") == 1
    return enter.get("nested") is None


def _performance(row: StateRow, progress: list[Event], times: list[float]) -> None:
    """Fill the time-weighted performance and the last progress of ``row`` from its samples."""
    weighted = weight = 0.0
    values: list[float] = []
    last: Event | None = None
    for begin, end in row.spans:
        inside = [
            e
            for e in progress[bisect_left(times, begin) : bisect_right(times, end)]
            if e.get("path") == row.path or str(e.get("path", "")).startswith(row.path + "/")
        ]
        for i, sample in enumerate(inside):
            last = sample
            value = sample.get("performance")
            if not isinstance(value, int | float) or isinstance(value, bool):
                continue
            held = (inside[i + 1].t if i + 1 < len(inside) else end) - sample.t
            weighted += value * held
            weight += held
            values.append(float(value))
    if weight > 0:
        row.performance = weighted / weight
    elif values:
        row.performance = sum(values) / len(values)
    if last is not None and isinstance(last.get("progress"), int | float):
        row.progress_end = float(last.get("progress"))


def _qualities(events: list[Event]) -> dict[str, dict[str, float]]:
    sums: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for event in events:
        measures = event.get("measures")
        if event.kind == "quality" and isinstance(measures, dict):
            for name, value in measures.items():
                if isinstance(value, int | float) and not isinstance(value, bool):
                    sums[str(event.get("service"))][name].append(float(value))
    return {s: {m: sum(v) / len(v) for m, v in ms.items()} for s, ms in sums.items()}


def build_report(run: Run, depth: str = "leaf") -> Report:
    """Table 7.9 for every agent of ``run``; ``depth`` is ``"leaf"`` or ``"top"``."""
    if depth not in ("leaf", "top"):
        raise ValueError(f"depth must be 'leaf' or 'top', not {depth!r}")
    report = Report(depth, notes=list(run.notes))
    for name, info in run.agents.items():
        events = list(run.of(name))
        spans, entered = _spans(events, info.finish, report.notes)
        total = info.duration
        agent = AgentReport(name, info.mission, info.plan, total, info.outcome, qualities=_qualities(events))
        progress = [e for e in events if e.kind == "progress"]
        times = [e.t for e in progress]
        for path, enter in entered.items():  # dicts keep the order of first entry
            if not _is_row(path, enter, depth):
                continue
            row = StateRow(name, path, str(enter.get("state") or path.rsplit("/", 1)[-1]))
            row.spans = sorted(spans[path])
            row.visits = [end - begin for begin, end in row.spans]
            row.contribution = [v / total if total > 0 else 0.0 for v in row.visits]
            _performance(row, progress, times)
            agent.rows.append(row)
        report.agents.append(agent)
    return report


def _joined(values: list[float], fmt: str) -> str:
    return "+".join(format(v, fmt) for v in values)


def format_table(report: Report) -> str:
    """Table 7.9: State | Execution Time (s) | Contribution to mission (%) | Avg. Performance."""
    header = ("State", "Execution Time (s)", "Contribution to mission (%)", "Avg. Performance")
    cells = [
        (
            row.label,
            _joined(row.visits, ".3f"),
            _joined([100 * c for c in row.contribution], ".1f"),
            "-" if row.performance is None else f"{row.performance:.2f}",
        )
        for row in report.rows
    ]
    widths = [max(len(c[i]) for c in [header, *cells]) for i in range(4)]

    def line(values: tuple[str, ...]) -> str:
        return "  ".join(v.ljust(w) for v, w in zip(values, widths, strict=True)).rstrip()

    out: list[str] = []
    rows = iter(cells)
    for agent in report.agents:
        about = f"mission {agent.mission or '?'}" + (f", plan {agent.plan}" if agent.plan else "")
        out.append(f"{agent.agent} ({about}): {agent.total:.3f} s, outcome {agent.outcome or 'none (no end event)'}")
        out.append(line(header))
        out.extend(line(next(rows)) for _ in agent.rows)
        for service, measures in agent.qualities.items():
            out.append(f"  quality {service}: " + ", ".join(f"{m} {v:.3g}" for m, v in measures.items()))
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def _signal_style(event: Event) -> tuple[str, str] | None:
    if event.kind == "signal":
        return ("^", "tab:green") if event.get("direction") == "sent" else ("v", "tab:blue")
    if event.kind == "agent-lost":
        return "X", "tab:red"
    if event.kind == "agent-found":
        return "P", "tab:olive"
    if event.kind == "agent-finished":  # the other agent ended its mission: finished, not lost
        return "s", "tab:gray"
    if event.kind == "signal-dropped":
        return "x", "tab:gray"
    return None


def write_plots(run: Run, out_dir: Path) -> list[Path]:
    """Per agent a Fig. 7.21/7.23-style PNG; with two or more agents a plan PNG too."""
    from matplotlib.figure import Figure  # no pyplot: no global backend, safe offscreen

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    leaf = build_report(run, "leaf")
    paths: list[Path] = []
    for agent in leaf.agents:
        events = list(run.of(agent.agent))
        by_path: dict[str, list[Event]] = defaultdict(list)
        for event in events:
            if event.kind == "progress" and isinstance(event.get("progress"), int | float):
                by_path[str(event.get("path"))].append(event)
        fig = Figure(figsize=(10, 8), layout="constrained")
        ax_progress, ax_state, ax_mission = fig.subplots(3, 1, sharex=True)
        for i, row in enumerate(agent.rows):
            color = f"C{i % 10}"
            for n, (begin, end) in enumerate(row.spans):
                samples = [e for e in by_path[row.path] if begin <= e.t <= end]
                ax_progress.plot(
                    [e.t for e in samples],
                    [e.get("progress") for e in samples],
                    color=color,
                    marker=".",
                    markersize=3,
                    label=row.label if n == 0 else None,
                )
            ax_state.broken_barh([(b, e - b) for b, e in row.spans], (i - 0.4, 0.8), color=color)
        ax_progress.set(ylim=(-0.05, 1.05), ylabel="progress", title="State progress")
        if agent.rows:
            ax_progress.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax_state.set_yticks(range(len(agent.rows)), [r.label for r in agent.rows], fontsize=7)
        ax_state.set(ylim=(len(agent.rows) - 0.5, -0.5), title="Active state")
        mission = [e for e in events if e.kind == "progress" and isinstance(e.get("mission_progress"), int | float)]
        steps = [(e.t, float(e.get("mission_progress"))) for e in mission]
        if steps:  # hold the last value until the agent's end
            steps.append((max(steps[-1][0], run.agents[agent.agent].finish), steps[-1][1]))
        ax_mission.step([t for t, _ in steps], [p for _, p in steps], where="post")
        ax_mission.set(ylim=(-0.05, 1.05), ylabel="progress", xlabel="run time (s)", title="Mission progress")
        fig.suptitle(f"Agent {agent.agent} — mission {agent.mission or '?'} ({agent.outcome or 'no end'})")
        path = out_dir / agent_file_name(agent.agent).replace(".jsonl", ".png")
        fig.savefig(path, dpi=100)
        paths.append(path)
    if len(leaf.agents) >= 2:
        paths.append(_plan_plot(run, leaf, out_dir / "plan.png"))
    return paths


def lane_label(agent: AgentReport) -> str:
    """An agent's lane in the plan plot: its name and how it ended (finished is never "lost")."""
    return f"{agent.agent}\n{'finished: ' + agent.outcome if agent.outcome else 'no end'}"


def _plan_plot(run: Run, leaf: Report, path: Path) -> Path:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 1.2 + 0.9 * len(leaf.agents)), layout="constrained")
    ax = fig.subplots()
    lanes = {a.agent: i for i, a in enumerate(leaf.agents)}
    colors: dict[str, str] = {}
    for agent in leaf.agents:
        y = lanes[agent.agent]
        for row in agent.rows:
            color = colors.setdefault(row.state, f"C{len(colors) % 10}")
            ax.broken_barh([(b, e - b) for b, e in row.spans], (y - 0.35, 0.7), color=color, alpha=0.8)
            for begin, end in row.spans:
                ax.text((begin + end) / 2, y, row.state, ha="center", va="center", fontsize=6, clip_on=True)
    for event in run.events:
        style = _signal_style(event)
        if style is None or event.agent not in lanes:
            continue
        marker, color = style
        lane = lanes[event.agent] - 0.45
        ax.plot([event.t], [lane], marker=marker, color=color, linestyle="none")
        other = event.kind.removeprefix("agent-")  # "lost" / "found" / "finished": the key naming the other agent
        if event.kind == "signal":
            label = event.get("name")
        elif event.kind == "signal-dropped":
            label = f"{event.get('name')} dropped ({event.get('to')} finished)"
        else:
            label = f"{other} {event.get(other)}"
        if event.kind == "agent-finished":
            label += f" ({event.get('outcome')})"
        ax.annotate(str(label), (event.t, lane), xytext=(2, -8), textcoords="offset points", fontsize=6)
    ax.set_yticks(range(len(lanes)), [lane_label(a) for a in leaf.agents])
    ax.set(ylim=(len(lanes) - 0.4, -0.8), xlabel="run time (s)")
    plans = sorted({a.plan for a in leaf.agents if a.plan})
    legend = "▲ signal sent, ▼ received, ✕ agent lost, + found, ■ finished"
    ax.set_title(f"Plan {', '.join(plans) or '?'}: active states ({legend})")
    fig.savefig(path, dpi=100)
    return path


def main(run_dir: Path, *, out: Path | None = None, json: bool = False, depth: str = "leaf") -> int:
    """Print Table 7.9 (and the JSON object last with ``json``) and write the plots; exit status."""
    try:
        run = read_run(Path(run_dir))
        report = build_report(run, depth)
    except (RunError, ValueError) as error:
        print(f"ckm-mission report: {error}", file=sys.stderr)
        return 1
    out_dir = Path(out) if out is not None else Path(run_dir) / "report"
    try:
        plots = write_plots(run, out_dir)
    except OSError as error:
        print(f"ckm-mission report: {out_dir}: cannot write the plots: {error.strerror or error}", file=sys.stderr)
        return 1
    for note in report.notes:
        print(f"note: {note}", file=sys.stderr)
    print(format_table(report), end="")
    print("plots: " + ", ".join(str(p) for p in plots))
    if json:
        print(jsonlib.dumps({"run_dir": str(run_dir), **report.to_json(), "plots": [str(p) for p in plots]}))
    return 0
