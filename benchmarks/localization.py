"""ckm-bench localization: Algorithm 3's reliability filter against an AMCL-like MCL (thesis §6.2.1, issue I).

Both filters see the same simulated scans (60 beams) and odometry, with the same seeds, on two
runs per world: a tour and a kidnapping in the use-case lab, in a generated floor plan of symmetric
rooms and in a warehouse of repeating aisles (identical rack rows, each of identical segments: where a
filter tracking a fetch gets lost). Every run starts from a uniform prior (global localization).

Per filter and particle count: position and heading RMSE over the steps after convergence,
time to converge, mean time to recover after the kidnapping — recovered when the estimate stays
within 0.45 m for more than 10 s (Fox et al.) —, failure rate (runs that never converge or never
recover) and milliseconds per update; the same per world (``worlds``: the lab, the floor plan, the aisles),
with the global-localization convergence rate (runs that converge from the uniform prior). A PNG
plots the error over time of both filters. ``--rooms`` sets the floor plan's identical rooms per
side (3), ``--worlds`` runs only some worlds.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from benchmarks.localization_worlds import WORLDS, Run, standard_runs
from plugins.localization.mcl import AmclFilter, MclSettings
from plugins.localization.odometry import wrap
from plugins.localization.reliability_filter import ReliabilityFilter, ReliabilitySettings

Array = npt.NDArray[np.float64]
PARTICLES = (500, 2500, 10000)
RECOVERED_M = 0.45
RECOVERED_S = 10.0
FILTERS = ("reliability", "mcl")


def make_filter(name: str, run: Run, particles: int, seed: int) -> AmclFilter | ReliabilityFilter:
    """A filter ``name`` (``reliability`` or ``mcl``) on ``run``'s map, from a uniform prior."""
    rng = np.random.default_rng(seed)
    angles = run.laser.angles()
    if name == "reliability":
        return ReliabilityFilter(run.grid, angles, ReliabilitySettings(particles=particles), rng)
    return AmclFilter(run.grid, angles, MclSettings(particles=particles), rng)


def settled_from(errors: Array, times: Array, start: int) -> float | None:
    """The first time at or after step ``start`` from which the error stays under 0.45 m for more than 10 s."""
    good = errors < RECOVERED_M
    k = start
    while k < len(errors):
        if not good[k]:
            k += 1
            continue
        end = k
        while end < len(errors) and good[end]:
            end += 1
        if times[end - 1] - times[k] > RECOVERED_S:
            return float(times[k])
        k = end
    return None


def play(name: str, run: Run, particles: int, seed: int) -> dict[str, Any]:
    """Run one filter over one run; its error series and the scores of the run."""
    flt = make_filter(name, run, particles, seed)
    poses = np.empty((len(run.truth), 3))
    start = time.perf_counter()
    for k in range(len(run.truth)):
        poses[k] = flt.update(run.odometry[k], run.scans[k]).pose
    elapsed = time.perf_counter() - start
    errors = np.hypot(poses[:, 0] - run.truth[:, 0], poses[:, 1] - run.truth[:, 1])
    heading = np.abs(wrap(poses[:, 2] - run.truth[:, 2]))
    times = run.times
    converged = settled_from(errors[: run.kidnap_step], times[: run.kidnap_step], 0)
    recovered = None
    if run.kidnap_step is not None and converged is not None:
        at = settled_from(errors, times, run.kidnap_step)
        recovered = None if at is None else at - float(times[run.kidnap_step])
    tracked = np.zeros(len(errors), dtype=bool)
    if converged is not None:
        tracked[times >= converged] = True
    return {
        "run": run.name,
        "errors": errors,
        "heading": heading,
        "tracked": tracked,
        "converged": converged,
        "recovered": recovered,
        "kidnapped": run.kidnap_step is not None,
        "ms": 1000.0 * elapsed / len(run.truth),
    }


def world_of(run_name: str) -> str:
    """The world a run's name starts with (``lab-tour`` → ``lab``)."""
    return next(w for w in WORLDS if run_name.startswith(w + "-"))


def by_world(plays: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per world: runs, global-localization convergence rate, failure rate, mean convergence and recovery times."""
    found: dict[str, dict[str, Any]] = {}
    for world in WORLDS:
        mine = [p for p in plays if world_of(p["run"]) == world]
        if not mine:
            continue
        converged = [p["converged"] for p in mine if p["converged"] is not None]
        kidnapped = [p for p in mine if p["kidnapped"]]
        recovered = [p["recovered"] for p in kidnapped if p["recovered"] is not None]
        failures = sum(p["converged"] is None or (p["kidnapped"] and p["recovered"] is None) for p in mine)
        found[world] = {
            "runs": len(mine),
            "converged_rate": len(converged) / len(mine),
            "failure_rate": failures / len(mine),
            "converge_s": float(np.mean(converged)) if converged else None,
            "recovered_rate": len(recovered) / len(kidnapped) if kidnapped else None,
            "recover_s": float(np.mean(recovered)) if recovered else None,
        }
    return found


def summarise(name: str, particles: int, beams: int, plays: list[dict[str, Any]]) -> dict[str, Any]:
    """The JSON object of one filter and particle count over all its runs."""
    tracked_err = np.concatenate([p["errors"][p["tracked"]] for p in plays])
    tracked_head = np.concatenate([p["heading"][p["tracked"]] for p in plays])
    converged = [p["converged"] for p in plays if p["converged"] is not None]
    recovered = [p["recovered"] for p in plays if p["recovered"] is not None]
    failures = sum(p["converged"] is None or (p["kidnapped"] and p["recovered"] is None) for p in plays)
    return {
        "name": name,
        "particles": particles,
        "beams": beams,
        "rmse_m": float(np.sqrt(np.mean(tracked_err**2))) if tracked_err.size else None,
        "heading_rmse_rad": float(np.sqrt(np.mean(tracked_head**2))) if tracked_head.size else None,
        "converge_s": float(np.mean(converged)) if converged else None,
        "recover_s": float(np.mean(recovered)) if recovered else None,
        "failure_rate": failures / len(plays),
        "ms_per_update": float(np.mean([p["ms"] for p in plays])),
        "runs": len(plays),
        "worlds": by_world(plays),
        "per_run": [
            {
                "run": p["run"],
                "converge_s": p["converged"],
                "recover_s": p["recovered"],
                "rmse_m": float(np.sqrt(np.mean(p["errors"][p["tracked"]] ** 2))) if p["tracked"].any() else None,
            }
            for p in plays
        ],
    }


def plot(series: dict[str, dict[str, Array]], runs: list[Run], png: Path) -> None:
    """Position error over time of both filters on each run (first seed, 2,500 particles or the largest count)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(len(runs), 1, figsize=(9, 2.4 * len(runs)), sharex=False)
    for ax, run in zip(np.atleast_1d(axes), runs, strict=True):
        for name, style in (("reliability", "-"), ("mcl", "--")):
            ax.plot(run.times, series[name][run.name], style, label=name)
        if run.kidnap_step is not None:
            ax.axvline(run.times[run.kidnap_step], color="red", lw=0.8, label="kidnapping")
        ax.axhline(RECOVERED_M, color="grey", lw=0.6, ls=":")
        ax.set_yscale("symlog", linthresh=0.1)
        ax.set_ylim(bottom=0.0)
        ax.set_title(run.name, fontsize=9)
        ax.set_ylabel("error (m)")
        ax.legend(fontsize=7, loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("time (s)")
    figure.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png, dpi=100)
    plt.close(figure)


def run(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Run the benchmark; the result dict (written as ``results.json`` with the plot in ``--out``)."""
    parser = argparse.ArgumentParser(prog="ckm-bench localization", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one seed, 500 and 2,500 particles only")
    parser.add_argument("--seeds", type=int, default=2, help="simulated data sets (each: two runs per world)")
    parser.add_argument("--particles", type=int, nargs="+", default=None, help="particle counts")
    parser.add_argument("--out", type=Path, default=Path("runs/bench-localization"), help="where the plot goes")
    parser.add_argument("--rooms", type=int, default=3, help="identical rooms per side of the floor plan's corridor")
    parser.add_argument("--worlds", nargs="+", choices=WORLDS, default=list(WORLDS), help="worlds to run")
    args = parser.parse_args(list(argv or []))
    if args.rooms < 2:
        parser.error(f"--rooms must be at least 2, not {args.rooms}")
    seeds = 1 if args.quick else args.seeds
    counts = tuple(args.particles or ((500, 2500) if args.quick else PARTICLES))
    datasets = [standard_runs(100 * s + 1, rooms=args.rooms, worlds=args.worlds) for s in range(seeds)]
    beams = datasets[0][0].laser.beams
    plot_count = 2500 if 2500 in counts else counts[-1]
    series: dict[str, dict[str, Array]] = {name: {} for name in FILTERS}
    rows = []
    for particles in counts:
        for name in FILTERS:
            plays = []
            for s, runs in enumerate(datasets):
                for r in runs:
                    played = play(name, r, particles, seed=1000 * s + 7)
                    plays.append(played)
                    if s == 0 and particles == plot_count:
                        series[name][r.name] = played["errors"]
            rows.append(summarise(name, particles, beams, plays))
    png = args.out / "localization-error.png"
    plot(series, datasets[0], png)
    result = {
        "filters": rows,
        "runs": [r.name for r in datasets[0]],
        "seeds": seeds,
        "rooms": args.rooms,
        "plot": str(png),
        "criterion": f"within {RECOVERED_M} m for more than {RECOVERED_S:g} s",
    }
    (args.out / "results.json").write_text(json.dumps(result, indent=2))
    return result


def _fmt(value: float | None, digits: int = 3, unit: str = "") -> str:
    return "never" if value is None else f"{value:.{digits}f}{unit}"


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """Table rows: one per filter and particle count."""
    rows = []
    for f in result["filters"]:
        rows.append(
            (
                f"{f['name']} {f['particles']} particles",
                f"rmse {_fmt(f['rmse_m'], 3, ' m')}, heading {_fmt(f['heading_rmse_rad'], 3, ' rad')}, "
                f"converge {_fmt(f['converge_s'], 1, ' s')}, recover {_fmt(f['recover_s'], 1, ' s')}, "
                f"fail {f['failure_rate']:.2f}, {f['ms_per_update']:.1f} ms",
            )
        )
        for world, w in f.get("worlds", {}).items():
            rows.append(
                (
                    f"  {world} ({w['runs']} runs)",
                    f"converged {w['converged_rate']:.2f} (in {_fmt(w['converge_s'], 1, ' s')}), "
                    f"recovered {'-' if w['recovered_rate'] is None else format(w['recovered_rate'], '.2f')} "
                    f"(in {_fmt(w['recover_s'], 1, ' s')}), fail {w['failure_rate']:.2f}",
                )
            )
    rows.append(("plot", result["plot"]))
    return rows
