"""Tables and figures of ``ckm-bench adaptation``: Table 7.3, Table 7.4, Fig. 7.8–7.10.

Table 7.3, per number of active clients (the phases of the schedule with that many clients,
pooled over the TCM runs): the share of the clients' quality samples in each resolution
(activation), the scenario changes (events) and raised alarms while that many clients were
connected, the mean deadline (QoS; the median too, a shared machine's stalls skew the mean) and
CPU share (QoC) the clients were told, and the penalty —
the mean over those samples of the largest ξ of the client's scenarios.

Table 7.4: variance, deviation, skewness and kurtosis (Pearson's, not excess: a uniform
distribution gives 1.8) of the time series, in TCM periods, of the mean active resolution
(VGA = 1, QVGA = 0.5, QQVGA = 0.25 of VGA's width), the mean deadline and the mean CPU share.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ckmconf.model.resources import SmartResource

RESOLUTION = {"VGA": 1.0, "QVGA": 0.5, "QQVGA": 0.25}


def _count_at(timeline: Sequence[tuple[float, int]], t: float) -> int:
    times = [when for when, _ in timeline]
    index = bisect.bisect_right(times, t) - 1
    return timeline[index][1] if index >= 0 else 0


def _messages(run: dict[str, Any], kind: str) -> list[dict[str, Any]]:
    return [m for record in run["clients"].values() for m in record[kind]]


def _moments(values: Sequence[float]) -> dict[str, float]:
    data = np.asarray(values, dtype=float)
    if data.size < 2:
        return {"variance": 0.0, "deviation": 0.0, "skewness": 0.0, "kurtosis": 0.0}
    centred = data - data.mean()
    m2, m3, m4 = (float(np.mean(centred**k)) for k in (2, 3, 4))
    return {
        "variance": m2,
        "deviation": math.sqrt(m2),
        "skewness": m3 / m2**1.5 if m2 > 0 else 0.0,
        "kurtosis": m4 / m2**2 if m2 > 0 else 0.0,
    }


def series(run: dict[str, Any], period: float) -> list[dict[str, float]]:
    """Per TCM period: mean resolution, deadline and CPU over the clients' quality samples."""
    bins: dict[int, list[dict[str, Any]]] = {}
    for message in _messages(run, "quality"):
        bins.setdefault(int(message["time"] / period), []).append(message)
    rows = []
    for index in sorted(bins):
        group = bins[index]
        deadlines = [m["measures"]["deadline"] for m in group if "deadline" in m["measures"]]
        cpus = [m["measures"]["cpu"] for m in group if "cpu" in m["measures"]]
        rows.append(
            {
                "time": index * period,
                "resolution": float(np.mean([RESOLUTION.get(m["scenario"], 0.0) for m in group])),
                "deadline": float(np.mean(deadlines)) if deadlines else math.nan,
                "cpu": float(np.mean(cpus)) if cpus else math.nan,
            }
        )
    return rows


def summarize(
    runs: Sequence[dict[str, Any]], baseline: dict[str, Any], resource: SmartResource, schedule: Sequence[int]
) -> dict[str, Any]:
    """Table 7.3 per client count and Table 7.4's moments, from the TCM ``runs`` and the ``baseline`` run."""
    service = resource.services[0]
    names = [s.name for s in service.scenarios]
    period = service.tcm.period if service.tcm else 0.5
    rows = []
    for count in sorted(set(schedule)):
        quality, events, alarms = [], 0, 0
        for run in runs:
            timeline = run["timeline"]
            quality += [m for m in _messages(run, "quality") if _count_at(timeline, m["time"]) == count]
            events += sum(1 for m in _messages(run, "events") if _count_at(timeline, m["time"]) == count)
            alarms += sum(
                1 for m in _messages(run, "alarms") if m["raised"] and _count_at(timeline, m["time"]) == count
            )
        total = max(1, len(quality))
        deadlines = [m["measures"]["deadline"] for m in quality if "deadline" in m["measures"]]
        cpus = [m["measures"]["cpu"] for m in quality if "cpu" in m["measures"]]
        rows.append(
            {
                "clients": count,
                "activation": {n: sum(m["scenario"] == n for m in quality) / total for n in names},
                "events": events,
                "alarms": alarms,
                "qos_deadline_s": float(np.mean(deadlines)) if deadlines else None,
                "qos_deadline_median_s": float(np.median(deadlines)) if deadlines else None,
                "qoc_cpu": float(np.mean(cpus)) if cpus else None,
                "penalty": float(np.mean([max(m["penalties"].values()) for m in quality])) if quality else 0.0,
                "samples": len(quality),
            }
        )
    pooled = [row for run in runs for row in series(run, period)]
    statistics = {
        key: _moments([r[key] for r in pooled if not math.isnan(r[key])]) for key in ("resolution", "deadline", "cpu")
    }
    return {
        "clients": rows,
        "switches_tcm": len(_messages(runs[0], "events")),
        "switches_threshold_baseline": len(_messages(baseline, "events")),
        "alarms_tcm": sum(m["raised"] for m in _messages(runs[0], "alarms")),
        "alarms_threshold_baseline": sum(m["raised"] for m in _messages(baseline, "alarms")),
        "statistics": statistics,
        "schedule": list(schedule),
        "runs": len(runs),
        "frames": runs[0]["frames"],
    }


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench adaptation``'s table (Table 7.3 per client count, then Table 7.4)."""
    lines = []
    for row in result["clients"]:
        shares = " ".join(f"{name} {share:.0%}" for name, share in row["activation"].items())
        deadline = "-" if row["qos_deadline_s"] is None else f"{row['qos_deadline_s'] * 1e3:.1f} ms"
        cpu = "-" if row["qoc_cpu"] is None else f"{row['qoc_cpu']:.0%}"
        lines.append(
            (
                f"{row['clients']} client(s)",
                f"{shares} | events {row['events']} alarms {row['alarms']} | {deadline} {cpu} | ξ {row['penalty']:.2f}",
            )
        )
    lines.append(("switches TCM / threshold", f"{result['switches_tcm']} / {result['switches_threshold_baseline']}"))
    lines.append(
        (
            "alarms judged TCM / threshold",
            f"{result.get('alarms_judged_tcm', '-')} / {result.get('alarms_judged_threshold_baseline', '-')}",
        )
    )
    lines.append(
        (
            "time in violation TCM / threshold",
            f"{result.get('violation_share_tcm', 0):.1%} / {result.get('violation_share_threshold_baseline', 0):.1%}",
        )
    )
    for key, moments in result["statistics"].items():
        lines.append((f"Table 7.4 {key}", " ".join(f"{k} {v:.3g}" for k, v in moments.items())))
    return lines


def _clip_outliers(ax: Any, run: dict[str, Any], service: Any, measure: str) -> None:
    """Keep the bounds readable: a machine stall (one sample of a second) would flatten the plot."""
    bounds = [p.upper for s in service.scenarios for p in s.policies if p.measure == measure and p.upper is not None]
    values = [m["measures"].get(measure) for r in run["clients"].values() for m in r["quality"]]
    values = [v for v in values if isinstance(v, int | float)]
    if not bounds or not values:
        return
    top = 3 * max(bounds)
    above = [v for v in values if v > top]
    if above:
        ax.set_ylim(0, top)
        ax.annotate(f"{len(above)} above, up to {max(above):.3g}", (0.01, 0.92), xycoords="axes fraction", fontsize=7)


def figures(run: dict[str, Any], baseline: dict[str, Any], resource: SmartResource, out: Path) -> list[Path]:
    """Fig. 7.8 (clients and alarms), Fig. 7.9 (result graph), Fig. 7.10 (scatter) as PNG files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    service = resource.services[0]
    period = service.tcm.period if service.tcm else 0.5
    levels = {s.name: i for i, s in enumerate(sorted(service.scenarios, key=lambda s: s.weight))}
    timeline = run["timeline"]
    paths = []

    fig, ax = plt.subplots(figsize=(8, 3))
    ax.step([t for t, _ in timeline], [c for _, c in timeline], where="post", label="active clients")
    raised = [m["time"] for m in _messages(run, "alarms") if m["raised"]]
    ax.plot(raised, [_count_at(timeline, t) + 0.15 for t in raised], "rv", label="alarm raised")
    switched = [m["time"] for m in _messages(run, "events")]
    ax.plot(switched, [_count_at(timeline, t) - 0.15 for t in switched], "k.", label="scenario change")
    ax.set(xlabel="time (s)", ylabel="clients", title="Fig. 7.8 — active clients and quality alarms")
    ax.legend(loc="upper right", fontsize=7)
    paths.append(out / "fig7_8_clients_alarms.png")
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(4, 2, figsize=(11, 10), sharex=True)
    for name, record in sorted(run["clients"].items()):
        quality = record["quality"]
        times = [m["time"] for m in quality]
        for col, measure in enumerate(("deadline", "cpu")):
            axes[0][col].plot(times, [m["measures"].get(measure, math.nan) for m in quality], lw=0.8, label=name)
        axes[1][0].step(times, [levels[m["scenario"]] for m in quality], where="post", lw=0.8, label=name)
        axes[2][0].plot(times, [max(m["penalties"].values()) for m in quality], lw=0.8, label=name)
    for col, measure in enumerate(("deadline", "cpu")):
        for scenario in service.scenarios:
            for policy in scenario.policies:
                if policy.measure == measure and policy.upper is not None:
                    axes[0][col].axhline(policy.upper, ls="--", lw=0.6, color="grey")
                    axes[0][col].annotate(scenario.name, (0, policy.upper), fontsize=6, color="grey")
        axes[0][col].set_title(f"{measure} (bounds dashed)")
        _clip_outliers(axes[0][col], run, service, measure)
    axes[1][0].set_yticks(list(levels.values()), list(levels))
    axes[1][0].set_title("active resolution (TCM)")
    for name, record in sorted(baseline["clients"].items()):
        quality = record["quality"]
        axes[1][1].step(
            [m["time"] for m in quality], [levels[m["scenario"]] for m in quality], where="post", lw=0.8, label=name
        )
    axes[1][1].set_yticks(list(levels.values()), list(levels))
    axes[1][1].set_title("active resolution (threshold baseline)")
    axes[2][0].set_title("penalty ξ (largest of the client's scenarios)")
    rows = series(run, period)
    axes[2][1].plot([r["time"] for r in rows], [r["resolution"] for r in rows], lw=0.8)
    axes[2][1].set_title("mean resolution (VGA = 1)")
    for data, style, label in ((run, "-", "TCM"), (baseline, "--", "threshold")):
        events = sorted(m["time"] for m in _messages(data, "events"))
        alarms = sorted(m["time"] for m in _messages(data, "alarms") if m["raised"])
        axes[3][0].step(events, range(1, len(events) + 1), style, where="post", label=f"events {label}")
        axes[3][1].step(alarms, range(1, len(alarms) + 1), style, where="post", label=f"alarms {label}")
    for ax in axes[3]:
        ax.set_xlabel("time (s)")
        ax.legend(fontsize=7)
    axes[0][0].legend(fontsize=6)
    fig.suptitle("Fig. 7.9 — qualities, resolutions, penalty, events and alarms")
    paths.append(out / "fig7_9_results.png")
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5, 4))
    ax.scatter([r["resolution"] for r in rows], [r["cpu"] for r in rows], s=8, alpha=0.6)
    ax.set(xlabel="mean resolution (VGA = 1)", ylabel="CPU share", title="Fig. 7.10 — resolution vs resources")
    paths.append(out / "fig7_10_scatter.png")
    fig.tight_layout()
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths
