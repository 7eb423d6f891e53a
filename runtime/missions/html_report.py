"""``ckm-mission report RUN_DIR --html``: one self-contained HTML page about a run (§7.4–7.5, issue K).

The page holds, with every picture embedded (base64 PNG, camera frames JPEG) and the CSS inline (no other file, no
network): the header (system, plan, agents and how each ended, mission time, run date, the
off-line validation verdict when ``RUN_DIR/validation.json`` holds ``ckm-mission validate --json``'s
object), Table 7.9 per agent (:func:`.report.build_report`) next to the rows of the reference
tables installed packages register (:mod:`.report_references`), the Fig. 7.23 progress plots
(:func:`.report.write_plots`), the Fig. 7.16
map (:mod:`.report_figures`, the configuration's ``<Environment>`` with the trajectories and
zoom-map areas of the run's bag, :mod:`.report_bag`), the Fig. 7.19 recognition reliability, each
agent's camera frames at the moments of Fig. 7.22 and 7.24 (entering and ending each state of its
mission's success route: :mod:`.report_snapshots`), the simulated world's scenario, disturbances and
final state (:mod:`.report_world`), and every problem of the run counted (:mod:`.report_problems`).
What a run lacks (no bag, no such topic, no configuration) is said where it would have been shown.
The configuration is the one ``stats.json`` names (or ``--config``); the bags are the rosbag2
folders in the run directory (or ``--bag``). The topics read and the states shown are the
configuration's own (:mod:`.report_topics`), those the command line names first.
"""

from __future__ import annotations

import datetime as dt
import json
import sys
import tempfile
from dataclasses import dataclass, field
from html import escape
from pathlib import Path

from ckmconf import ConfigError, load
from ckmconf.model import System

from .recording import Run, RunError, read_run
from .report import AgentReport, Report, build_report, write_plots
from .report_bag import BagData, Moment, ReportTopics, find_bags, read_bags
from .report_problems import Problems, collect
from .report_references import ReferenceTable, compare, installed_tables
from .report_snapshots import snapshots_section
from .report_topics import key_states, recognising_states, topics_of
from .report_views import map_section, note, png_tag, reliability_section
from .report_world import world_rows
from .validation.online import replay

CSS = """
body{font-family:sans-serif;max-width:1100px;margin:1em auto;color:#222}
h1{font-size:1.5em}h2{border-bottom:1px solid #ccc;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;font-size:.9em}
th{background:#eee}td.num{text-align:right;font-family:monospace}
.note{color:#7d6608;background:#fef9e7;padding:2px 6px}.error{color:#922b21;background:#fdedec;padding:2px 6px}
.ok{color:#1e8449;font-weight:bold}.bad{color:#922b21;font-weight:bold}
table.snapshots td{vertical-align:top;text-align:center;font-size:.85em}table.snapshots img{max-width:250px}
img{max-width:100%}
"""


@dataclass
class Options:
    """What ``--html`` may be told: the configuration, the bags, topics, the target object.

    ``topics`` it names are read instead of the configuration's (:func:`.report_topics.topics_of`);
    ``snapshot_states`` (state names or paths) instead of each agent's key states
    (:func:`.report_topics.key_states`, every state it entered without the configuration's mission).
    """

    config: Path | None = None
    bags: list[Path] | None = None
    topics: ReportTopics = field(default_factory=ReportTopics)
    target: str | None = None
    snapshot_states: tuple[str, ...] | None = None


def _table(header: list[str] | None, rows: list[list[str]], css: str = "") -> str:
    """A table whose cells are already escaped HTML; numeric-looking cells right-aligned."""
    head = "<tr>" + "".join(f"<th>{h}</th>" for h in header) + "</tr>" if header else ""
    body = "".join(
        "<tr>" + "".join(f'<td class="num">{c}</td>' if c[:1].isdigit() else f"<td>{c}</td>" for c in row) + "</tr>"
        for row in rows
    )
    return f'<table class="{css}">{head}{body}</table>'


def _system(run_dir: Path, options: Options, notes: list[str]) -> tuple[System | None, Path | None, str | None]:
    """The run's configuration (``--config``, else what ``stats.json`` names, or a ``stats-NODE.json``
    of a ``--node`` process sharing the run directory) and the system name."""
    named: str | None = None
    name: str | None = None
    for stats in [run_dir / "stats.json", *sorted(run_dir.glob("stats-*.json"))]:
        if not stats.is_file() or named:
            continue
        try:
            record = json.loads(stats.read_text(encoding="utf-8"))
            named, name = record.get("config"), record.get("system")
        except (OSError, ValueError, AttributeError) as error:
            notes.append(f"{stats}: unreadable ({error}); the configuration is not known from it")
    path = options.config
    if path is None and named:
        tries = [Path(named), run_dir / named, run_dir.parent / named]
        path = next((p for p in tries if p.is_file()), None)
        if path is None:
            notes.append(f"configuration {named} (stats.json) not found; give it with --config")
    if path is None:
        if named is None:
            notes.append("no configuration (no stats.json naming it, no --config): no map, no success finals")
        return None, None, name
    try:
        system = load(path)
    except (ConfigError, OSError) as error:
        notes.append(f"configuration {path} does not load: {error}")
        return None, path, name
    return system, path, system.name


def _outcome(agent: AgentReport, system: System | None) -> str:
    """How the agent ended: success (its mission's first final), another final, crashed, stopped."""
    if agent.outcome is None:
        return '<span class="bad">no end event (crashed or killed)</span>'
    mission = system.mission(agent.mission) if system is not None and agent.mission else None
    finals = [f.name for f in mission.finals] if mission is not None else []
    if finals and agent.outcome == finals[0]:
        return f'<span class="ok">success</span> ({escape(agent.outcome)})'
    if finals and agent.outcome in finals:
        return f'<span class="bad">final {escape(agent.outcome)}</span> (success is {escape(finals[0])})'
    if agent.outcome in ("crashed", "stopped"):
        return f'<span class="bad">{escape(agent.outcome)}</span>'
    return escape(agent.outcome) + ("" if finals else " (mission not in the configuration: success unknown)")


def _validation(run_dir: Path) -> str:
    """The off-line validation verdict kept with the run (``validation.json``: ``ckm-mission validate --json``)."""
    path = run_dir / "validation.json"
    if not path.is_file():
        return "not in the run directory (validation.json: the last line of <code>ckm-mission validate --json</code>)"
    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines() if line.strip().startswith("{")]
        verdict = json.loads(lines[-1]) if lines else None
    except (OSError, ValueError) as error:
        return f'<span class="bad">{escape(str(path))}: unreadable: {escape(str(error))}</span>'
    if not isinstance(verdict, dict) or "ok" not in verdict:
        return f'<span class="bad">{escape(str(path))}: not the output of ckm-mission validate --json</span>'
    missions = ", ".join(
        f"{escape(str(m.get('mission')))} {'coherent' if m.get('ok') else 'NOT coherent'}"
        for m in verdict.get("missions", [])
        if isinstance(m, dict)
    )
    head = '<span class="ok">passed</span>' if verdict["ok"] else '<span class="bad">FAILED</span>'
    return head + (f" ({missions})" if missions else "")


def _replays(run: Run, report: Report, system: System | None) -> str:
    """Whether each agent's recorded states follow an off-line episode of its mission (§7.5)."""
    if system is None:
        return "no configuration: the off-line episodes cannot be explored"
    lines = []
    for agent in report.agents:
        if agent.mission is None or system.mission(agent.mission) is None:
            continue
        verdict = replay(system, agent.mission, agent.agent, run.of(agent.agent))
        css = "ok" if verdict.reproduced else "bad" if verdict.divergence else ""
        lines.append(f'<span class="{css}">{escape(verdict.describe())}</span>' if css else escape(verdict.describe()))
    return "<br>".join(lines) or "no agent with a mission of the configuration"


def _origin(run: Run) -> float | None:
    """The epoch time of the recordings' run time 0 (``start.wall − t``), None without a wall clock."""
    walls = [e.get("wall") - e.t for e in run.events if e.kind == "start" and isinstance(e.get("wall"), int | float)]
    return min(walls) if walls else None


def _header(
    run: Run, report: Report, system: System | None, config: Path | None, name: str | None, problems: Problems
) -> str:
    origin = _origin(run)
    begin = min((a.begin for a in run.agents.values()), default=0.0)
    finish = max((a.finish for a in run.agents.values()), default=0.0)
    date = (
        dt.datetime.fromtimestamp(origin + begin, dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
        if origin is not None
        else "unknown"
    )
    plans = sorted({a.plan for a in report.agents if a.plan}) or ["none recorded"]
    rows = [
        ["System", escape(name or "unknown")],
        ["Configuration", escape(str(config) if config else "unknown")],
        ["Plan", escape(", ".join(plans))],
        ["Run date", date],
        ["Mission time", f"{finish - begin:.1f} s"],
        ["Off-line validation", _validation(run.run_dir)],
        ["Off-line vs on-line", _replays(run, report, system)],
        *world_rows(run.run_dir),
        ["Problems", f'<a href="#problems">{problems.total} in {len(problems.problems)} kind(s)</a>'],
    ]
    agents = [
        [escape(a.agent), escape(a.mission or "?"), _outcome(a, system), f"{a.total:.1f} s"] for a in report.agents
    ]
    return _table(None, rows, "summary") + _table(["Agent", "Mission", "Outcome", "Time"], agents, "agents")


def _joined(values: list[float] | tuple[float, ...], fmt: str) -> str:
    return "+".join(format(v, fmt) for v in values) or "-"


def _reference(table: ReferenceTable, agent: AgentReport) -> str:
    """``table``'s rows that stand for states of ``agent``, next to the run's figures ("" if none do)."""
    matched = compare(table, agent)
    if not matched:
        return ""
    cells = [
        [
            escape(c.reference.state),
            escape(", ".join(c.rows)),
            _joined(c.reference.times, ".3f"),
            _joined(c.times, ".3f"),
            _joined([100 * x for x in c.reference.contributions], ".1f"),
            _joined([100 * x for x in c.contributions], ".1f"),
            f"{c.reference.performance:.2f}",
            "-" if c.performance is None else f"{c.performance:.2f}",
        ]
        for c in matched
    ]
    header = ["Reference state", "Our states", "Time ref. (s)", "Time run (s)", "Contrib. ref. (%)"]
    header += ["Contrib. run (%)", "Perf. ref.", "Perf. run"]
    return f"<p>Next to {escape(table.source)}:</p>" + _table(header, cells, f"reference agent-{escape(agent.agent)}")


def _table_7_9(report: Report) -> str:
    """Table 7.9 per agent (the columns of :func:`.report.format_table`), then each installed
    reference table's rows that stand for its states (:mod:`.report_references`)."""
    tables, problems = installed_tables()
    out = []
    for agent in report.agents:
        rows = [
            [
                escape(r.label),
                _joined(r.visits, ".3f"),
                _joined([100 * c for c in r.contribution], ".1f"),
                "-" if r.performance is None else f"{r.performance:.2f}",
            ]
            for r in agent.rows
        ]
        out.append(f"<h3>{escape(agent.agent)} — mission {escape(agent.mission or '?')}</h3>")
        header = ["State", "Execution Time (s)", "Contribution to mission (%)", "Avg. Performance"]
        out.append(_table(header, rows, f"table79 agent-{escape(agent.agent)}"))
        for service, measures in agent.qualities.items():
            values = ", ".join(f"{escape(m)} {v:.3g}" for m, v in measures.items())
            out.append(f"<p>Quality of {escape(service)}: {values}</p>")
        for table in tables:
            out.append(_reference(table, agent))
    out.extend(note(problem) for problem in problems)
    return "".join(out)


def _progress(run: Run) -> str:
    """Fig. 7.23: the plan plot (two agents or more) and each agent's progress plot."""
    with tempfile.TemporaryDirectory(prefix="ckm-report-") as scratch:
        paths = write_plots(run, Path(scratch))
        paths.sort(key=lambda p: p.name != "plan.png")
        return "".join(png_tag(p.read_bytes(), f"Fig. 7.23 {p.stem}") for p in paths)


def _snapshot_states(run: Run, report: Report, system: System | None) -> tuple[str, ...]:
    """The paths of the states whose moments are shown: each agent's key states
    (:func:`.report_topics.key_states`), or every behavior state it entered when the configuration
    does not have its mission."""
    paths: list[str] = []
    for agent in report.agents:
        known = key_states(system, agent.mission) if system is not None and agent.mission else None
        if known is None:
            entered = (e for e in run.events if e.agent == agent.agent and e.kind == "enter" and not e.get("nested"))
            known = tuple(str(e.get("path")) for e in entered)
        paths += known
    return tuple(dict.fromkeys(paths))


def _moments(run: Run, states: tuple[str, ...], origin: float | None) -> list[Moment]:
    """Each agent entering and leaving one of ``states`` (names or paths; Fig. 7.22 / 7.24), on the
    bags' epoch clock."""
    if origin is None:
        return []
    return [
        Moment(origin + e.t, e.t, e.agent, str(e.get("state")), str(e.get("path")), _edge(e.kind, e.get("reason")))
        for e in run.events
        if e.kind in ("enter", "exit") and (e.get("state") in states or e.get("path") in states)
    ]


def _labels(states: tuple[str, ...]) -> list[str]:
    """State paths without their top mission (``Navigation/NAV``), once each, to name them in a note."""
    return list(dict.fromkeys(s.split("/", 1)[-1] for s in states))


def _edge(kind: str, reason: object) -> str:
    """How a moment came: the state ``entered``, ``ended`` by a transition, or ``stopped`` with the run."""
    return "entered" if kind == "enter" else "stopped" if reason == "stopped" else "ended"


def _problems(problems: Problems) -> str:
    """Every problem with its count; warnings of the logs apart, folded."""
    if not problems.problems:
        out = note("No problem recorded: no error in the logs, no alarm, no agent lost, no task failure.")
    else:
        rows = [
            [escape(p.severity), escape(p.source), escape(p.what), str(p.count), escape(p.example)]
            for p in problems.problems
        ]
        out = f"<p>{problems.total} problem(s) of {len(problems.problems)} kind(s).</p>"
        out += _table(["Severity", "Where", "What", "Count", "Example"], rows, "problems")
    if problems.warnings:
        rows = [[escape(p.source), escape(p.what), str(p.count)] for p in problems.warnings]
        total = sum(p.count for p in problems.warnings)
        out += f"<details><summary>{total} log warning(s)</summary>"
        out += _table(["Where", "What", "Count"], rows, "warnings") + "</details>"
    return out


def _sources(run: Run, data: BagData, notes: list[str]) -> str:
    """What the report was made from, and the notes on what was missing or skipped."""
    files = sorted({e.source.split(":", 1)[0] for e in run.events})
    out = f"<p>Recordings: {escape(', '.join(files))} in {escape(str(run.run_dir))}.</p>"
    if data.bags:
        rows = [[escape(t), escape(k), str(data.stored.get(t, 0))] for t, k in sorted(data.topics.items())]
        out += f"<p>Bags: {escape(', '.join(str(b) for b in data.bags))}.</p>"
        out += _table(["Topic", "Type", "Messages"], rows, "topics")
    else:
        out += note("No bag in the run directory (record one with ckm-run --record TOPICS): no map trajectories, "
                    "no recognition plot, no camera frames.")  # fmt: skip
    out += "".join(note(e, "error") for e in data.errors)
    out += "".join(note(n) for n in [*notes, *run.notes])
    return out


def build_html(run_dir: Path, options: Options | None = None) -> tuple[str, list[str]]:
    """The report page of the run in ``run_dir``, and the errors to tell the user (a corrupt bag).

    Raises:
        RunError: the run directory has no readable recording.
    """
    options = options or Options()
    run = read_run(run_dir)
    report = build_report(run, "leaf")
    notes: list[str] = []
    system, config, name = _system(run_dir, options, notes)
    topics = options.topics.filled_from(topics_of(system)) if system is not None else options.topics
    origin = _origin(run)
    states = options.snapshot_states
    if states is None:
        states = _snapshot_states(run, report, system)
    moments = _moments(run, states, origin)
    missions = {a.mission for a in report.agents if a.mission}
    recognising = recognising_states(system, missions, topics) if system is not None else set()
    bags = options.bags if options.bags is not None else find_bags(run_dir)
    data = read_bags(bags, topics, moments)
    if origin is None:
        notes.append("the recordings have no wall time: the bag's times are shown from its first message")
    first = min((m[0][0] for m in data.poses.values() if m), default=0.0)
    zero = origin if origin is not None else first

    def clock(t: float) -> float:
        return t - zero

    problems = collect(run_dir, run)
    plans = ", ".join(sorted({a.plan for a in report.agents if a.plan})) or "-"
    title = f"Run report: {name or 'unknown system'}, plan {plans}"
    sections = [
        f"<h1>{escape(title)}</h1>",
        _header(run, report, system, config, name, problems),
        "<h2>Table 7.9: time, contribution and performance per state</h2>",
        _table_7_9(report),
        "<h2>Fig. 7.23: state and mission progress</h2>",
        _progress(run),
        "<h2>Fig. 7.16: map, trajectories and zoom-map areas</h2>",
        map_section(system, config, data, topics, clock),
        "<h2>Fig. 7.19: recognition reliability along the approach</h2>",
        reliability_section(data, topics, report, options.target, clock, recognising),
        "<h2>Fig. 7.22 / 7.24: camera frames at the mission's key moments</h2>",
        snapshots_section(data, topics, moments, _labels(states)),
        '<h2 id="problems">Problems seen in the run</h2>',
        _problems(problems),
        "<h2>Data sources and notes</h2>",
        _sources(run, data, notes),
    ]
    page = f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{escape(title)}</title>'
    page += f"<style>{CSS}</style></head><body>{''.join(sections)}</body></html>\n"
    return page, list(data.errors)


def main(run_dir: Path, *, out: Path | None = None, options: Options | None = None) -> int:
    """Write the report (``RUN_DIR/report.html`` by default); 1 when it could not be written or a bag is corrupt."""
    target = Path(out) if out is not None else Path(run_dir) / "report.html"
    try:
        page, errors = build_html(Path(run_dir), options)
    except RunError as error:
        print(f"ckm-mission report: {error}", file=sys.stderr)
        return 1
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(page, encoding="utf-8")
    except OSError as error:
        print(f"ckm-mission report: {target}: cannot write the report: {error.strerror or error}", file=sys.stderr)
        return 1
    for problem in errors:
        print(f"ckm-mission report: {problem}", file=sys.stderr)
    print(f"report: {target}")
    return 1 if errors else 0
