"""``ckm-bench rates [--duration S] [--run RUN_DIR …]``: Table 7.8 from the stand-in remote device and,
side by side, from the real use-case services of recorded simulated runs (issue J point 8, D191).

The stand-in measurement (:mod:`benchmarks.rates`) times three periodic kernel tasks publishing
realistic payloads over CKMultiPeer. A recorded run of the simulated laboratory (``ckm-run
configs/usecase/lab.xml --record …``) holds what the real services published: Pan-Tilt Recog.
(``/pantilt/objects``, the Nao camera's service, set rate 0.5 s), Navigation (``/nav/pose``, 0.8 s)
and Global Recog. Fusion (``/recog/objects``, 0.8 s), each a Smart Resource service that publishes
when a fresh input arrives. A bag's message time is the publisher's stamp on the run's clock
(simulated seconds under ``--time-scale``), so a run gives each service's achieved publication rate
and its spread; transport delays are not in a bag (only the live stand-in measures them).
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from runtime.ros.bag import BagError, BagSource

from . import rates

#: Table 7.8's services in the use case: the topic each publishes, in the run's bag.
REAL_TOPICS: dict[str, str] = {"Pan-Tilt Camera": "/pantilt/objects", "Navigation": "/nav/pose",
                               "Global Recog.": "/recog/objects"}  # fmt: skip


def from_run(run_dir: Path, warmup: int = 1) -> dict[str, Any]:
    """The publication periods of the real services recorded in ``run_dir``'s bag.

    Raises:
        ValueError: no bag in ``run_dir``, or none of the three topics recorded (named).
    """
    bag = run_dir / "bag"
    if not (bag / "metadata.yaml").is_file():
        raise ValueError(f"{run_dir}: no bag (a run recorded with ckm-run --record)")
    try:
        source = BagSource(bag, topics=None)
        recorded = source.topic_types()
        wanted = {name: topic for name, topic in REAL_TOPICS.items() if topic in recorded}
        if not wanted:
            raise ValueError(f"{bag}: none of {', '.join(REAL_TOPICS.values())} recorded")
        times: dict[str, list[float]] = {topic: [] for topic in wanted.values()}
        for topic, _type, stamp, _data in BagSource(bag, topics=wanted.values()).records():
            times[topic].append(stamp * 1e-9)
    except BagError as error:
        raise ValueError(str(error)) from None
    services = []
    for name, topic in REAL_TOPICS.items():
        kept = sorted(times.get(topic, []))[warmup:]
        periods = [b - a for a, b in itertools.pairwise(kept)]
        mean, std = rates._mean_std(periods)
        thesis = rates.THESIS[name]
        services.append({
            "name": name, "topic": topic, "recorded": topic in times, "set_rate_s": rates.SET_RATES[name],
            "samples": len(kept), "avg_rate_s": rates._round(mean), "rate_std_s": rates._round(std),
            "min_period_s": rates._round(min(periods)) if periods else None,
            "max_period_s": rates._round(max(periods)) if periods else None,
            "thesis_avg_rate_s": thesis["avg_rate_s"], "thesis_rate_std_s": thesis["rate_std_s"],
        })  # fmt: skip
    return {"run": str(run_dir), "services": services}


def run_cli(argv: Sequence[str]) -> dict[str, Any]:
    """``ckm-bench rates`` with its options: the stand-in device, then every ``--run``'s real services."""
    parser = argparse.ArgumentParser(prog="ckm-bench rates", description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds the stand-in device publishes")
    parser.add_argument("--run", type=Path, action="append", default=[],
                        help="a recorded run of the simulated lab (its bag): its real services' rates too")
    parser.add_argument("--no-stand-in", action="store_true", help="only the recorded runs")
    args = parser.parse_args(list(argv))
    result: dict[str, Any] = {}
    real = []
    for run_dir in args.run:  # checked first: a bad directory fails before a 30 s measurement
        try:
            real.append(from_run(run_dir))
        except ValueError as error:
            parser.error(f"--run: {error}")
    if not args.no_stand_in:
        result = rates.run(args.duration)
    result["real_runs"] = real
    return result


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The stand-in's rows (if measured), then per recorded run each real service's rate beside the thesis'."""
    rows = rates.describe(result) if "services" in result else []
    for run in result.get("real_runs", []):
        rows.append(("recorded run", f"{run['run']} (periods on the run's clock: simulated seconds)"))
        for s in run["services"]:
            if not s["recorded"]:
                rows.append((f"{s['name']} (real): {s['topic']}", "not recorded"))
                continue
            rows.append((
                f"{s['name']} (real, {s['topic']}): avg. rate / std.",
                f"{rates._s(s['avg_rate_s'])} s / {rates._ms(s['rate_std_s'])} ms ({s['samples']} samples) | "
                f"{rates._s(s['thesis_avg_rate_s'])} s / {rates._ms(s['thesis_rate_std_s'])} ms",
            ))  # fmt: skip
    return rows
