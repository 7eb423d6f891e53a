"""ckm-mission validate SYSTEM.xml [--mission NAME] [--json] [--run-dir DIR] | ckm-mission report RUN_DIR.

``validate`` is the off-line validation of §5.4 and Fig. 7.21, for the named mission or every
top mission (those no other mission nests): (a) the static checks of the mission graph, (b) a run
in simulated time against simulated services with the fake interaction forcing every transition
— state and transition coverage, each episode's state sequence — and (c) SRFlowGen's trace of
the quality requirements through the services (eq. 5.2–5.7). Findings are printed one per line,
``FILE:LINE:COL: XPATH: [kind] message``; then (d) each plan's wait-for graph
(:mod:`.validation.plans`: deadlocks, late signals, signals off the sender's success path). Exit
0 when no mission and no plan has an error, 1 otherwise (a file that does not load has every
problem reported like ``ckm-validate`` and exits 1). ``--run-dir`` keeps the
episodes' recordings (``ckm-mission report DIR/MISSION/episode-1`` draws Fig. 7.21).

``report`` prints Table 7.9 for a recorded run and writes its Fig. 7.23-style plots; with ``--html``
it writes one self-contained HTML page about the run instead (:mod:`.html_report`, docs/report.md).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ckmconf import ConfigError, load
from ckmconf.loader import LoadResult
from ckmconf.model import System
from ckmconf.model.missions import Plan, Validation

from . import report
from .fake import Coverage, explore, record_into
from .validation.check import top_missions as top_missions  # re-exported: the one implementation
from .validation.findings import Finding, finding, ordered


def _coverage_findings(system: System, mission: str, coverage: Coverage, required: float) -> list[Finding]:
    found = []
    for record, transition in coverage.uncovered():
        found.append(
            finding(
                "uncovered-transition",
                "error",
                f"no simulated run could fire {transition.from_} -> {transition.to} (when {transition.when!r}): its "
                "state is never reached or an earlier transition always holds first",
                transition,
                mission=record.name,
                state=transition.from_,
                transition=f"{transition.from_} -> {transition.to}",
            )
        )
    for episode in coverage.episodes:
        if episode.problem:
            last = episode.states[-1] if episode.states else None
            message = f"simulated run stopped at {last}: {episode.problem}"
            found.append(finding("run-stuck", "error", message, system.mission(mission), mission=mission))
    states, transitions = coverage.share()
    if min(states, transitions) < required:
        found.append(
            finding(
                "coverage",
                "error",
                f"coverage {states:.0%} of the states and {transitions:.0%} of the transitions is below "
                f"the required {required:.0%}",
                system.mission(mission),
                mission=mission,
            )
        )
    return found


def validate_mission(system: System, mission: str, run_dir: Path | None = None) -> dict[str, Any]:
    """Every check on one top mission: its findings, coverage, episodes and SRFlowGen report."""
    from .validation.plans import assumable_signals
    from .validation.srflowgen import srflowgen
    from .validation.static import check_mission

    settings = system.validation or Validation()
    findings = list(check_mission(system, mission))
    recorder = record_into(run_dir / mission) if run_dir is not None else None
    signals = assumable_signals(system, mission)
    coverage = explore(
        system, mission, step=settings.step, horizon=settings.horizon, recorder=recorder, signals=signals
    )
    findings += _coverage_findings(system, mission, coverage, settings.coverage)
    flow_findings, flow = srflowgen(system, mission, settings)
    findings += flow_findings
    states, transitions = coverage.share()
    return {
        "mission": mission,
        "ok": not any(f.severity == "error" for f in findings),
        "findings": [f.to_json() for f in ordered(findings)],
        "coverage": {"states": states, "transitions": transitions},
        "episodes": [
            {"outcome": e.outcome, "time": e.time, "states": e.states, "problem": e.problem} for e in coverage.episodes
        ],
        "flow": flow.to_json() if hasattr(flow, "to_json") else None,
        "_findings": ordered(findings),
    }


def _plans_of(system: System, mission: str | None) -> list[Plan]:
    """The plans to check: every one, or those with an agent running ``mission`` (or nesting it)."""
    if mission is None:
        return list(system.plans)
    from .fake import missions_below

    return [p for p in system.plans if any(mission in missions_below(system, a.mission) for a in p.agents)]


def _validate(args: argparse.Namespace) -> int:
    from .validation.plans import check_plan

    try:
        result = load(args.system, strict=False)
    except RecursionError:
        result = LoadResult(None, [ConfigError(args.system, 1, 1, "/", "elements are nested too deeply")])
    if result.errors or result.system is None:
        for error in result.errors:  # every load problem, as ckm-validate lists them
            print(error, file=sys.stderr)
        return 1
    system = result.system
    if system.validation is None:
        defaults = Validation()
        print(f"{args.system}: no <Validation> in this file, so the defaults apply (pMin {defaults.p_min:g}, "
              f"kMax {defaults.k_max}, coverage {defaults.coverage:.0%}); when a plan file includes this one and "
              "sets them, validate that file instead", file=sys.stderr)  # fmt: skip
    names = [args.mission] if args.mission else top_missions(system)
    if args.mission and system.mission(args.mission) is None:
        known = ", ".join(m.name for m in system.missions) or "none"
        print(f"{args.system}: no mission {args.mission!r} (missions: {known})", file=sys.stderr)
        return 1
    if not names:
        print(f"{args.system}: no mission to validate", file=sys.stderr)
        return 1
    results = [validate_mission(system, name, args.run_dir) for name in names]
    for outcome in results:
        for item in outcome.pop("_findings"):
            print(item.format())
        coverage = outcome["coverage"]
        verdict = "coherent" if outcome["ok"] else "NOT coherent"
        print(
            f"{outcome['mission']}: {verdict}; coverage {coverage['states']:.0%} of states, "
            f"{coverage['transitions']:.0%} of transitions in {len(outcome['episodes'])} simulated runs"
        )
    plans = []
    for plan in _plans_of(system, args.mission):
        plan_findings = check_plan(system, plan)
        for item in plan_findings:
            print(item.format())
        plan_ok = not any(f.severity == "error" for f in plan_findings)
        print(f"plan {plan.name}: {'coherent' if plan_ok else 'NOT coherent'} ({len(plan.agents)} agents)")
        plans.append({"plan": plan.name, "ok": plan_ok, "findings": [f.to_json() for f in plan_findings]})
    ok = all(r["ok"] for r in results) and all(p["ok"] for p in plans)
    if args.json:
        print(json.dumps({"ok": ok, "missions": results, "plans": plans}))
    return 0 if ok else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``ckm-mission``: ``validate`` (§5.4, Fig. 7.21) or ``report`` (Table 7.9); exit status."""
    parser = argparse.ArgumentParser(prog="ckm-mission", description="Validate missions off-line; report runs.")
    commands = parser.add_subparsers(dest="command", required=True)
    validate = commands.add_parser("validate", help="off-line validation (§5.4, Fig. 7.21)")
    validate.add_argument("system", help="System file")
    validate.add_argument("--mission", help="only this mission (default: every top mission)")
    validate.add_argument("--json", action="store_true", help="end with one line of JSON")
    validate.add_argument("--run-dir", type=Path, help="keep the simulated runs' recordings here")
    rep = commands.add_parser("report", help="on-line evaluation of a recorded run (Table 7.9, Fig. 7.23)")
    rep.add_argument("run_dir", type=Path)
    rep.add_argument("--out", type=Path, help="plots directory (default: RUN_DIR/report)")
    rep.add_argument("--json", action="store_true", help="end with one line of JSON")
    rep.add_argument("--depth", choices=("leaf", "top"), default="leaf", help="rows per behavior state or top state")
    _html_arguments(rep)
    args = parser.parse_args(argv)
    if args.command == "validate":
        return _validate(args)
    if args.html:
        if args.json or args.depth != "leaf":
            parser.error("--html goes without --json and --depth (the page has leaf rows and no JSON)")
        return _html_report(args)
    return report.main(args.run_dir, out=args.out, json=args.json, depth=args.depth)


def _html_arguments(rep: argparse.ArgumentParser) -> None:
    """``report --html``: one self-contained HTML page (runtime.missions.html_report). A topic not
    named here is the configuration's own (runtime.missions.report_topics)."""
    html = rep.add_argument_group("--html", "one self-contained HTML page; --out names it (RUN_DIR/report.html)")
    html.add_argument("--html", action="store_true", help="write the HTML report instead of the table and plots")
    html.add_argument("--config", type=Path, help="the run's System file (default: the one stats.json names)")
    html.add_argument("--bag", type=Path, action="append", help="a rosbag2 bag to read (default: those in RUN_DIR)")
    html.add_argument("--target", help="words naming the target object (default: the one recognised most reliably)")
    defaults = {
        "pose": "estimated pose topic (default: the pose Output of the configuration's navigation or localization "
        "service)",
        "truth": "ground-truth pose topic (default: those of the configuration's simulated true-pose sensors)",
        "camera": "camera image topic (default: the configuration's image topics)",
        "zoom": "zoom-map area topic (default: the zoom Output of the services giving the pose estimate)",
    }
    html.add_argument("--pose-topic", help=defaults["pose"])
    html.add_argument("--truth-topic", action="append", help=defaults["truth"])
    html.add_argument("--camera-topic", action="append", help=defaults["camera"])
    html.add_argument("--zoom-topic", action="append", help=defaults["zoom"])


def _html_report(args: argparse.Namespace) -> int:
    from . import html_report
    from .report_bag import ReportTopics

    topics = ReportTopics(
        estimate=args.pose_topic or "",
        truth=tuple(args.truth_topic or ()),
        cameras=tuple(args.camera_topic or ()),
        zoom=tuple(args.zoom_topic or ()),
    )
    options = html_report.Options(config=args.config, bags=args.bag, topics=topics, target=args.target)
    return html_report.main(args.run_dir, out=args.out, options=options)


if __name__ == "__main__":
    sys.exit(main())
