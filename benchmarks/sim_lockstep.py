"""The real-time factor of a whole simulated system run by ``ckm-run --lockstep`` (issue J point 5 and
9, D190, D192): the node's scheduler, its sensors, controllers and actuators, the world server and
the network, every process on the run's lock-step clock.

:func:`lockstep_factor` runs the system (by default configs/examples/sim_station.xml: an arm with
a wrist depth camera, a rover with a lidar, encoders and a bumper, sensors at 0.02-0.5 s) twice on
a private loopback network, for a short and a long simulated duration; the difference of their wall
times is the cost of the extra simulated seconds without the start-up (building the world, joining
the network), so ``factor`` = extra simulated seconds / extra wall seconds (above 1: faster than
real time).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import ckmconf
from ckmconf.model import Network

from .netbench import private_settings

REPO = Path(__file__).resolve().parent.parent
STATION = REPO / "configs" / "examples" / "sim_station.xml"
SHORT = 0.5  # simulated seconds of the run that measures the start-up alone
STEP = 0.01  # the lock-step clock's largest move, s


def _run(config: Path, duration: float, run_dir: Path) -> float:
    """Wall seconds of ``ckm-run CONFIG --lockstep STEP --duration DURATION``."""
    command = [sys.executable, "-m", "runtime.cli", str(config), "--lockstep", str(STEP), "--duration", str(duration),
               "--log-dir", str(run_dir)]  # fmt: skip
    start = time.perf_counter()
    done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=600 + 60 * duration)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"ckm-run --lockstep exited {done.returncode}: {done.stderr.strip()[-500:]}")
    return wall


def lockstep_factor(config: Path = STATION, duration: float = 20.0) -> dict[str, Any]:
    """Simulated seconds per wall second of ``config`` run in lock-step (see the module docstring)."""
    system = ckmconf.load(config)
    with tempfile.TemporaryDirectory(prefix="ckm-bench-lockstep-") as folder:
        private = Path(folder) / config.name
        network = Network(**{**private_settings("multipeer"), "interface": "127.0.0.1"})
        ckmconf.dump(dataclasses.replace(system, network=network), private)
        short = _run(private, SHORT, Path(folder) / "short")
        long = _run(private, duration, Path(folder) / "long")
    extra = max(long - short, 1e-3)
    return {"system": config.name, "simulated_s": duration, "wall_s": round(long, 2), "startup_wall_s": round(short, 2),
            "factor": round((duration - SHORT) / extra, 2), "step_s": STEP}  # fmt: skip
