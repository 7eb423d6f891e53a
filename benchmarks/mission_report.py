"""``ckm-bench mission``'s summary: per plan, success rate, mission time and Table 7.9's columns over N runs.

One run's figures come from its recording (:func:`runtime.missions.recording.read_run`) through
:func:`runtime.missions.report.build_report` at leaf depth, so a state is a behavior state of one
agent, named ``AGENT: LABEL`` (``turtlebot: Navigation/NAV``): the same name in both plans, so the
individual and the cooperative missions stand side by side.

Per plan (decision D163):

- **success rate**: successful runs / runs, with its Wilson score 95 % interval (a few runs: the
  normal approximation would leave [0, 1]);
- **mission time**: the span from the first agent's ``start`` to the last agent's ``end``
  (simulated seconds under ``--time-scale``), mean and median over the successful runs — a failed
  run ends at a timeout or a failure, not at the mission's end (``mean_all_mission_s`` takes every
  recorded run);
- **per state**, over the successful runs (every recorded run when none succeeded:
  ``states_from``): the mean and median of its time per run (its visits summed), the mean share of
  its agent's mission time (``contribution``), the mean of its time-weighted average performance
  (eq. 5.1, runs where it had samples), how many runs visited it, and every run's time (the plot);
- **thesis**: each Table 7.9 row (:mod:`ckm_lab.table_7_9`) next to the mean time of
  the states it stands for;
- **realtime factor**: recorded mission seconds / wall seconds of the ``ckm-run`` processes.
- **mission realtime factor**: recorded mission seconds / wall seconds from the first agent's start
  to the last agent's end (their ``real`` stamps, D248): the same without start-up and shutdown.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ckm_lab.table_7_9 import TABLE_7_9

from runtime.missions.report import Report
from runtime.missions.report_references import compare

Z95 = 1.959964


def wilson(successes: int, runs: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (0–1 bounds; (0, 1) for no runs)."""
    if runs <= 0:
        return 0.0, 1.0
    p = successes / runs
    centre = p + z * z / (2 * runs)
    half = z * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs))
    scale = 1 + z * z / runs
    return max(0.0, (centre - half) / scale), min(1.0, (centre + half) / scale)


def state_figures(report: Report) -> dict[str, dict[str, Any]]:
    """One run's states (leaf rows): ``AGENT: LABEL`` → time, contribution, performance."""
    states: dict[str, dict[str, Any]] = {}
    for agent in report.agents:
        for row in agent.rows:
            states[f"{agent.agent}: {row.label}"] = {
                "time_s": round(row.time, 6),
                "contribution": round(sum(row.contribution), 6),
                "performance": None if row.performance is None else round(row.performance, 6),
            }
    return states


def thesis_figures(report: Report) -> dict[str, float]:
    """One run's time (s) per Table 7.9 row, from the states each row stands for."""
    out: dict[str, float] = {}
    for agent in report.agents:
        for comparison in compare(TABLE_7_9, agent):
            out[comparison.reference.state] = out.get(comparison.reference.state, 0.0) + sum(comparison.times)
    return out


def _mean(values: Sequence[float]) -> float | None:
    return round(statistics.fmean(values), 6) if values else None


def _median(values: Sequence[float]) -> float | None:
    return round(statistics.median(values), 6) if values else None


def summarise(plan: str, results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The plan's summary over its ``results`` (the runner's per-run records, see the module docstring)."""
    runs = len(results)
    successes = [r for r in results if r["success"]]
    recorded = [r for r in results if r["mission_s"] is not None]
    low, high = wilson(len(successes), runs)
    basis = successes or recorded
    names: list[str] = []
    for r in basis:
        names.extend(n for n in r["states"] if n not in names)
    states = []
    for name in names:
        seen = [r["states"][name] for r in basis if name in r["states"]]
        times = [s["time_s"] for s in seen]
        rated = [s["performance"] for s in seen if s["performance"] is not None]
        states.append(
            {
                "name": name,
                "runs": len(seen),
                "mean_s": _mean(times),
                "median_s": _median(times),
                "contribution": _mean([s["contribution"] for s in seen]),
                "avg_performance": _mean(rated),
                "times_s": times,
            }
        )
    thesis = []
    for row in TABLE_7_9.rows:
        ours = [r["thesis"][row.state] for r in basis if row.state in r.get("thesis", {})]
        if ours:
            thesis.append(
                {"state": row.state, "thesis_s": round(sum(row.times), 3), "mean_s": _mean(ours), "runs": len(ours)}
            )
    wall = sum(r["wall_s"] for r in recorded)
    phased = [r for r in recorded if r.get("mission_wall_s")]
    phase = sum(r["mission_wall_s"] for r in phased)
    disturbed = [r for r in results if r.get("disturbed")]  # a --scenario's runs it did disturb
    return {
        "plan": plan,
        "runs": runs,
        "successes": len(successes),
        "success_rate": len(successes) / runs if runs else 0.0,
        "success_ci95": [round(low, 4), round(high, 4)],
        "mean_mission_s": _mean([r["mission_s"] for r in successes]),
        "median_mission_s": _median([r["mission_s"] for r in successes]),
        "mean_all_mission_s": _mean([r["mission_s"] for r in recorded]),
        "realtime_factor": round(sum(r["mission_s"] for r in recorded) / wall, 4) if wall > 0 else None,
        "mission_realtime_factor": round(sum(r["mission_s"] for r in phased) / phase, 4) if phase > 0 else None,
        "states_from": "successful" if successes else "all",
        "disturbed": len(disturbed),
        "handled": sum(1 for r in disturbed if r.get("handled")),
        "states": states,
        "thesis": thesis,
    }


def _num(value: float | None, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """Table rows: per plan its success rate and mission time, then each state across the plans."""
    plans = result["plans"]
    rows: list[tuple[str, str]] = [("plans", " | ".join(p["plan"] for p in plans))]
    rows.append(
        (
            "success rate (Wilson 95 %)",
            " | ".join(
                f"{p['successes']}/{p['runs']} = {p['success_rate']:.2f} [{p['success_ci95'][0]:.2f}, "
                f"{p['success_ci95'][1]:.2f}]"
                for p in plans
            ),
        )
    )
    rows.append(
        (
            "mission time mean / median (s)",
            " | ".join(f"{_num(p['mean_mission_s'])} / {_num(p['median_mission_s'])}" for p in plans),
        )
    )
    rows.append(("realtime factor", " | ".join(_num(p["realtime_factor"], 3) for p in plans)))
    rows.append(("mission realtime factor", " | ".join(_num(p.get("mission_realtime_factor"), 3) for p in plans)))
    scenario = result.get("scenario")
    if scenario:
        kill = ""
        if scenario["kill_agent"]:
            kill = f", kills agent {scenario['kill_agent']} {scenario['kill_after']:g} s in"
        rows.append(("scenario", f"{scenario['name']} (expects {scenario['expect']}{kill})"))
        rows.append(
            (
                "handled as the missions say",
                " | ".join(f"{p.get('handled', 0)}/{p.get('disturbed', 0)} disturbed runs" for p in plans),
            )
        )
    names: list[str] = []
    for p in plans:
        names.extend(s["name"] for s in p["states"] if s["name"] not in names)
    for name in names:
        cells = []
        for p in plans:
            s = next((s for s in p["states"] if s["name"] == name), None)
            cells.append(
                "-"
                if s is None
                else f"{_num(s['mean_s'])} s, {100 * (s['contribution'] or 0):.0f} %, "
                f"perf {_num(s['avg_performance'], 2)} (n={s['runs']})"
            )
        rows.append((f"  {name}", " | ".join(cells)))
    thesis_states: list[str] = []
    for p in plans:
        thesis_states.extend(t["state"] for t in p["thesis"] if t["state"] not in thesis_states)
    for state in thesis_states:
        cells, reference = [], None
        for p in plans:
            t = next((t for t in p["thesis"] if t["state"] == state), None)
            cells.append("-" if t is None else f"{_num(t['mean_s'])} s")
            reference = reference if t is None else t["thesis_s"]
        rows.append((f"  Table 7.9 {state} ({_num(reference)} s)", " | ".join(cells)))
    if result.get("plot"):
        rows.append(("plot", result["plot"]))
    return rows


def plot(plans: Sequence[dict[str, Any]], path: Path) -> Path:
    """Box plots of each state's time per run, the plans side by side per state (PNG at ``path``)."""
    from matplotlib.figure import Figure  # no pyplot: no global backend, safe offscreen (Agg)

    names: list[str] = []
    for p in plans:
        names.extend(s["name"] for s in p["states"] if s["name"] not in names)
    fig = Figure(figsize=(10, 1.5 + 0.45 * max(1, len(names)) * max(1, len(plans))), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / max(1, len(plans))
    drawn = False
    for k, p in enumerate(plans):
        by_name = {s["name"]: s["times_s"] for s in p["states"]}
        data = [(i, by_name[n]) for i, n in enumerate(names) if by_name.get(n)]
        if not data:
            continue
        positions = [i - 0.4 + width * (k + 0.5) for i, _ in data]
        boxes = ax.boxplot(
            [d for _, d in data],
            positions=positions,
            widths=width * 0.9,
            orientation="horizontal",
            patch_artist=True,
            manage_ticks=False,
            medianprops={"color": "black"},
        )
        for patch in boxes["boxes"]:
            patch.set_facecolor(f"C{k}")
            patch.set_alpha(0.6)
        ax.plot([], [], color=f"C{k}", linewidth=8, alpha=0.6, label=f"{p['plan']} ({p['states_from']} runs)")
        drawn = True
    ax.set_title("ckm-bench mission: time per state over the runs (Table 7.9's execution time)")
    if names:
        ax.set_yticks(range(len(names)), names, fontsize=7)
        ax.set(ylim=(len(names) - 0.5, -0.5), xlabel="time in the state per run (s)")
    else:  # every run failed before a state was recorded: say so, not an empty frame
        ax.text(0.5, 0.5, "no run recorded a state", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
    if drawn:
        ax.legend(loc="lower right", fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return path
