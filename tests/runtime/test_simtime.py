"""A run on a scaled clock (runtime.simtime, ``ckm-run --time-scale``): every clock of every process
of the run advances at the scale, sleeps last the scaled time, bad scales are refused."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from runtime import simtime
from tests.conftest import REPO

PROBE = """
import json, time
import runtime
from runtime import simtime
w0, m0, p0 = time.time(), time.monotonic(), time.perf_counter()
real = simtime._REAL["monotonic"]
r0 = real()
time.sleep(0.2)
r1 = real()
print(json.dumps({"scale": simtime.scale(), "wall": r1 - r0, "mono": time.monotonic() - m0,
                  "time": time.time() - w0, "perf": time.perf_counter() - p0}))
"""


def probe(env: dict[str, str]) -> dict[str, float]:
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, env={**os.environ, **env},
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.returncode == 0, done.stderr
    result: dict[str, float] = json.loads(done.stdout)
    return result


def test_a_process_on_a_scale_sleeps_and_reads_scaled_time() -> None:
    figures = probe(simtime.environment(0.25))
    assert figures["scale"] == 0.25
    assert figures["wall"] >= 0.2 / 0.25 - 0.01  # a 0.2 s sleep takes 0.8 wall seconds
    for clock in ("mono", "time", "perf"):
        assert figures[clock] == pytest.approx(0.25 * figures["wall"], rel=0.05, abs=0.01), clock


WAITS = """
import json, queue, threading
import runtime
from runtime import simtime
real = simtime._REAL["monotonic"]
r0 = real()
threading.Event().wait(0.1)
r1 = real()
try:
    queue.Queue().get(timeout=0.1)
except queue.Empty:
    pass
print(json.dumps({"event": r1 - r0, "queue": real() - r1}))
"""


def test_a_process_on_a_scale_waits_on_events_and_queues_the_scaled_time() -> None:
    done = subprocess.run([sys.executable, "-c", WAITS], cwd=REPO, env={**os.environ, **simtime.environment(0.25)},
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout)
    # 0.1 s of the run's clock is 0.4 wall seconds: a loop paced by Event.wait keeps its period
    assert figures["event"] >= 0.4 - 0.01 and figures["queue"] >= 0.4 - 0.01


def test_without_a_scale_the_clocks_are_the_wall_clocks() -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CKM_TIME_")}
    done = subprocess.run([sys.executable, "-c", "from runtime import simtime; print(simtime.scale())"], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.stdout.strip() == "1.0"


@pytest.mark.parametrize(
    ("text", "message"), [("0", r"not in \(0, 1\]"), ("2", "never sped up"), ("fast", "not a number")]
)
def test_bad_scales_are_refused(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        simtime.parse_scale(text)


def test_a_malformed_origin_is_refused_naming_the_variable() -> None:
    with pytest.raises(ValueError, match="CKM_TIME_ORIGIN"):
        simtime.install({simtime.SCALE_VARIABLE: "0.5", simtime.ORIGIN_VARIABLE: "yesterday"})


def test_ckm_run_on_a_scale_runs_its_duration_in_scaled_seconds(tmp_path: Path) -> None:
    """A 1 s run at scale 0.5 lasts about 2 wall seconds, and its periodic tasks run 1 s worth of periods."""
    run = tmp_path / "run"
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "runtime.cli", str(REPO / "configs/examples/closed_loop.xml"),
                           "--duration", "1", "--time-scale", "0.5", "--log-dir", str(run)],
                          cwd=REPO, capture_output=True, text=True, timeout=120)  # fmt: skip
    elapsed = time.monotonic() - started
    assert done.returncode == 0, done.stderr
    assert elapsed >= 2.0
    stats = json.loads((run / "stats.json").read_text())
    tasks = {name: t for node in stats["nodes"].values() for name, t in node["tasks"].items()}
    fast = min(tasks.values(), key=lambda t: t["period_s"])
    assert fast["releases"] <= 1.3 / fast["period_s"]  # scaled seconds, not the ~2 wall seconds


def test_ckm_run_refuses_a_bad_scale() -> None:
    done = subprocess.run([sys.executable, "-m", "runtime.cli", str(REPO / "configs/examples/closed_loop.xml"),
                           "--time-scale", "3"], cwd=REPO, capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.returncode == 2 and "--time-scale" in done.stderr and "never sped up" in done.stderr
