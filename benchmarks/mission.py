"""ckm-bench mission: the use case's missions over N seeds, individual vs cooperative (thesis §7.5, Table 7.9).

Per seed ``k`` a randomised copy of the configuration (:mod:`benchmarks.mission_random`, any
configuration: the movable objects' poses, every mobile robot's start, sensor noise and the world's
seed, as its ``<Validation><Randomise>`` says; one line per seed says what moved) runs once per
plan — the same copy for every plan, so the plans are compared on the same draws — with
``ckm-run COPY --plan PLAN --duration D [--time-scale S] --log-dir OUT/runs/PLAN-seedK`` in its own
process group, bounded by a wall timeout (``D / S`` plus a margin: SIGINT, then SIGKILL). Its
output goes to ``OUT/runs/PLAN-seedK.log``.

A run succeeds when ``ckm-run`` exits 0, every agent of the plan recorded the first
``<Final>`` of its mission as its outcome (the missions list the success final first), and, when
the run had a simulated world, the world's own final record (``sim-final.json``) has the target
on the drop table (``object_home``: the robots did the work, not only the missions' bookkeeping). Its mission
time and per-state figures come from the recording (:mod:`benchmarks.mission_report`). The
summary (``OUT/summary.json``, the ``--json`` line) and a box plot of each state's time per plan
(``OUT/mission-states.png``) follow. ``--no-randomise`` runs the configuration as it is (any
configuration with plans: the tests use ``configs/examples/plan_two_agents.xml``).

``--layout compact`` runs the compact copy of the lab (:mod:`benchmarks.mission_compact`: the
drop table and the start next to the workbench; the same system, a shorter fetch) under the
randomisation; ``--lockstep STEP`` passes ``ckm-run --lockstep STEP`` (D190). ``--ports DISCOVERY BASE``
runs a copy whose ``<Network>`` has these discovery and base ports (:func:`layout_config`), so a bench can
run beside another one (or a lab run) on the same machine.

``--scenario NAME`` disturbs every run on purpose — a box in the corridor, the target moved during
the approach, the object dropped on the way home, the humanoid's process killed — and records in
each run and in the summary what was done and whether the missions handled it as they say
(:mod:`benchmarks.mission_scenarios`, issue K point 3).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import ckmconf
from benchmarks.mission_compact import compact
from benchmarks.mission_random import NS, Q, randomise
from benchmarks.mission_report import describe, plot, state_figures, summarise, thesis_figures
from benchmarks.mission_scenarios import (
    Scenario,
    check,
    choose,
    environment,
    judge,
    object_home,
    run_evidence,
    run_split,
)
from runtime.missions.recording import Run, RunError, read_run
from runtime.missions.report import build_report

__all__ = ["collect", "describe", "layout_config", "on_ports", "run", "run_once"]
DEFAULT_CONFIG = Path("configs/usecase/lab.xml")
MARGIN_S = 120.0  # wall seconds beyond duration / scale: start-up (verification, the world server) and stop
LOCKSTEP_WALL_PER_SIM_S = 12.0  # a lock-step clock runs as fast as the machine can: bounded, not paced (D190)
STOP_GRACE_S = 30.0  # after SIGINT, before SIGKILL


def success_finals(config: Path, plan: str) -> dict[str, str]:
    """Each agent of ``plan`` → the first ``<Final>`` of its mission (its success outcome)."""
    system = ckmconf.load(config)
    found = system.plan(plan)
    if found is None:
        names = ", ".join(p.name for p in system.plans) or "none"
        raise ValueError(f"{config}: no plan {plan!r} (plans: {names})")
    finals = {}
    for agent in found.agents:
        mission = system.mission(agent.mission)
        if mission is None or not mission.finals:
            raise ValueError(f"{config}: plan {plan}: agent {agent.name}'s mission {agent.mission!r} has no <Final>")
        finals[agent.name] = mission.finals[0].name
    return finals


def collect(run_dir: Path, exit_code: int | None, finals: dict[str, str]) -> dict[str, Any]:
    """One run's record from its directory: success, outcomes, mission time, states, Table 7.9 rows."""
    record: dict[str, Any] = {
        "run_dir": str(run_dir),
        "exit_code": exit_code,
        "success": False,
        "outcomes": dict.fromkeys(finals),
        "mission_s": None,
        "mission_wall_s": None,
        "states": {},
        "thesis": {},
        "error": None,
    }
    try:
        recorded = read_run(run_dir)
    except RunError as error:
        record["error"] = str(error)
        return record
    report = build_report(recorded, "leaf")
    for name, agent in recorded.agents.items():
        record["outcomes"][name] = agent.outcome
    begin = min(a.begin for a in recorded.agents.values())
    record["mission_s"] = round(max(a.finish for a in recorded.agents.values()) - begin, 6)
    record["mission_wall_s"] = mission_wall(recorded)
    record["states"] = state_figures(report)
    record["thesis"] = {k: round(v, 6) for k, v in thesis_figures(report).items()}
    record["success"] = exit_code == 0 and all(record["outcomes"].get(a) == f for a, f in finals.items())
    return record


def mission_wall(recorded: Run) -> float | None:
    """Wall seconds from the first agent's start to the last agent's end, on the machine's own clock
    (the events' ``real``, D248): the mission without the run's start-up and shutdown. None if an
    agent that started has no end (killed, or cut off by the bench's timeout): its phase is unknown."""

    def stamps(kind: str) -> dict[str, float]:
        return {e.agent: t for e in recorded.events if e.kind == kind and isinstance(t := e.get("real"), int | float)}

    starts, ends = stamps("start"), stamps("end")
    if not starts or set(starts) - set(ends):
        return None
    first, last = min(starts.values()), max(ends.values())
    return round(last - first, 3) if last > first else None


def run_once(
    config: Path,
    plan: str,
    run_dir: Path,
    *,
    duration: float,
    time_scale: float | None,
    log: Path,
    timeout: float | None = None,
    env: Mapping[str, str] | None = None,
    lockstep: float | None = None,
    record: str | None = None,
) -> tuple[int | None, float]:
    """Run ``ckm-run`` on ``config`` with ``plan`` into ``run_dir``; (exit code or None on a timeout, wall s).

    ``timeout`` (wall seconds) defaults to ``duration / time_scale`` plus :data:`MARGIN_S` (in lock-step,
    :data:`LOCKSTEP_WALL_PER_SIM_S` wall seconds per simulated one: the clock waits for the machine); ``env``
    is added to the run's environment (a world scenario).
    """
    command = [sys.executable, "-m", "runtime.cli", str(config), "--plan", plan, "--duration", f"{duration:g}"]
    command += ["--log-dir", str(run_dir)]
    if time_scale is not None:
        command += ["--time-scale", f"{time_scale:g}"]
    if lockstep is not None:
        command += ["--lockstep", f"{lockstep:g}"]
    if record:
        command += ["--record", record]
    if timeout is None:
        pace = LOCKSTEP_WALL_PER_SIM_S if lockstep is not None else 1.0 / (time_scale or 1.0)
        timeout = duration * pace + MARGIN_S
    log.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with log.open("w") as out:
        out.write("$ " + " ".join(command) + "\n")
        out.flush()
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                   env={**os.environ, **(env or {})})  # fmt: skip
        try:
            code: int | None = process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            code = None
            _stop(process)
            out.write(f"\nckm-bench mission: timed out after {timeout:.0f} s wall\n")
        except KeyboardInterrupt:  # its own session does not get the terminal's SIGINT: pass it on
            _stop(process)
            raise
    return code, time.monotonic() - started


def _run(
    config: Path,
    plan: str,
    run_dir: Path,
    scenario: Scenario | None,
    duration: float,
    scale: float | None,
    logs: Path,
    lockstep: float | None = None,
    record: str | None = None,
) -> tuple[int | None, float]:
    """One run of the benchmark, disturbed as ``scenario`` says: split over processes to kill an agent."""
    log = logs / f"{run_dir.name}.log"
    if scenario is None or scenario.kill_agent is None:
        return run_once(config, plan, run_dir, duration=duration, time_scale=scale, log=log, env=environment(scenario),
                        lockstep=lockstep, record=record)  # fmt: skip
    started = time.monotonic()
    log.parent.mkdir(parents=True, exist_ok=True)
    code = run_split(config, plan, run_dir, scenario, duration=duration, time_scale=scale, log=log,
                     timeout=duration / (scale or 1.0) + MARGIN_S)  # fmt: skip
    return code, time.monotonic() - started


def _stop(process: subprocess.Popen[bytes]) -> None:
    """Stop the run's process group: SIGINT (a clean stop: actuators safe, recordings closed), then SIGKILL."""
    try:
        os.killpg(process.pid, signal.SIGINT)
        try:
            process.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:  # it ended in between
        pass
    process.wait()


def on_ports(config: Path, out_dir: Path, ports: tuple[int, int]) -> Path:
    """Copy ``config``'s directory to ``out_dir`` with every ``<Network>``'s ``discoveryPort`` and ``basePort``
    set to ``ports``; the copy's System file (validated).

    Raises:
        ValueError: the configuration (its System file and Parts) has no ``<Network>``; ckmconf.ConfigError:
            the copy is invalid.
    """
    config = Path(config)
    if out_dir.exists():
        shutil.rmtree(out_dir)
    shutil.copytree(config.parent, out_dir)
    ET.register_namespace("", NS)
    for path in sorted(out_dir.glob("*.xml")):
        tree = ET.parse(path)
        elements = list(tree.getroot().iter(Q + "Network"))
        for element in elements:
            element.set("discoveryPort", str(ports[0]))
            element.set("basePort", str(ports[1]))
        if elements:
            tree.write(path, encoding="UTF-8", xml_declaration=True)
    copy = out_dir / config.name
    network = ckmconf.load(copy).network
    if network is None or (network.discovery_port, network.base_port) != ports:  # none in its own Parts
        raise ValueError(f"{config}: no <Network> to give the ports {ports[0]} {ports[1]}")
    return copy


def layout_config(config: Path, layout: str, out: Path, ports: tuple[int, int] | None = None) -> Path:
    """The System file the runs start from: ``config`` itself, or its copy under ``out/configs`` with the
    compact ``layout`` and/or the network ``ports`` (discovery, base). The randomised copies are made from it.

    Raises:
        ValueError, OSError, ckmconf.ConfigError: the copy cannot be made (see :func:`compact`, :func:`on_ports`).
    """
    if layout == "compact":
        return compact(config, out / "configs" / "compact", ports=ports)
    if ports is not None:
        return on_ports(config, out / "configs" / "ports", ports)
    return config


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ckm-bench mission", description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="System file (default: the lab)")
    parser.add_argument("--plans", nargs="+", default=["individual", "cooperative"], help="plans to run")
    parser.add_argument("--runs", type=int, default=20, help="seeds (runs per plan)")
    parser.add_argument("--first-seed", type=int, default=1, help="seed of the first run")
    parser.add_argument("--duration", type=float, default=400.0, help="ckm-run --duration (simulated s)")
    parser.add_argument("--time-scale", type=float, default=0.2, help="ckm-run --time-scale (0 for none)")
    parser.add_argument("--out", type=Path, default=Path("runs/bench-mission"), help="copies, runs, summary, plot")
    parser.add_argument("--no-randomise", action="store_true", help="run the configuration as it is")
    parser.add_argument(
        "--layout",
        choices=("lab", "compact"),
        default="lab",
        help="compact: the drop table and the start next to the workbench (a short fetch)",
    )
    parser.add_argument("--lockstep", type=float, help="ckm-run --lockstep STEP (simulated s): lock-step time")
    parser.add_argument(
        "--ports",
        type=int,
        nargs=2,
        metavar=("DISCOVERY", "BASE"),
        help="run a copy on these network ports (its <Network> discoveryPort and basePort)",
    )
    parser.add_argument(
        "--record", metavar="TOPICS", help="ckm-run --record TOPICS in every run (to see afterwards why one failed)"
    )
    parser.add_argument("--noise-scale", type=float, default=1.0, help="multiplies the sensor noise (0: none)")
    parser.add_argument(
        "--scenario",
        help="disturb every run: blocked-path, moved-object, dropped-object, "
        "lost-humanoid, or a FILE.scenario of world events (benchmarks/mission_scenarios.py)",
    )
    parser.add_argument("--kill-agent", help="kill the process of this plan agent in every run (a split run)")
    parser.add_argument(
        "--kill-after", type=float, help="simulated s after that agent's mission started (default 5, lost-humanoid 1)"
    )
    return parser


def run(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Run the benchmark; the result dict (also ``OUT/summary.json``; the plot in ``OUT``)."""
    parser = _parser()
    args = parser.parse_args(list(argv or []))
    if args.runs < 1:
        parser.error(f"--runs must be at least 1, not {args.runs}")
    if args.duration <= 0:
        parser.error(f"--duration must be positive, not {args.duration}")
    if not 0 <= args.time_scale <= 1:
        parser.error(f"--time-scale must be in (0, 1] (0: none), not {args.time_scale}")
    if args.lockstep is not None and not args.lockstep > 0:
        parser.error(f"--lockstep must be positive, not {args.lockstep}")
    if args.noise_scale < 0:
        parser.error(f"--noise-scale must not be negative, not {args.noise_scale}")
    ports: tuple[int, int] | None = None if args.ports is None else (args.ports[0], args.ports[1])
    if ports is not None and (not all(1024 <= p <= 65535 for p in ports) or ports[0] == ports[1]):
        parser.error(f"--ports must be two different ports in 1024-65535, not {ports[0]} {ports[1]}")
    try:
        finals = {plan: success_finals(args.config, plan) for plan in args.plans}
        scenario = choose(args.scenario, args.kill_agent, args.kill_after)
        if scenario is not None:
            check(scenario, args.config, args.plans)
            if args.lockstep is not None and scenario.kill_agent is not None:
                raise ValueError("--lockstep cannot run a split run (a killed agent): its processes share no clock")
            if args.record and scenario.kill_agent is not None:
                raise ValueError("--record cannot record a split run (a killed agent): one process per node")
    except (ckmconf.ConfigError, ValueError, OSError) as error:
        parser.error(str(error))
    # lock-step time has no scale: the clock waits for the machine (ckm-run refuses both)
    scale = None if args.lockstep is not None else args.time_scale or None
    out: Path = args.out
    results: dict[str, list[dict[str, Any]]] = {plan: [] for plan in args.plans}
    try:
        base = layout_config(args.config, args.layout, out, ports)
    except (ckmconf.ConfigError, ValueError, OSError) as error:
        parser.error(str(error))
    for seed in range(args.first_seed, args.first_seed + args.runs):
        config, changed = base, None
        if not args.no_randomise:
            try:
                randomised = randomise(base, seed, out / "configs" / f"seed{seed}", noise_scale=args.noise_scale)
            except (ckmconf.ConfigError, ValueError) as error:
                parser.error(f"seed {seed}: cannot randomise {base}: {error}")
            config, changed = randomised.config, randomised.to_json()
            print(randomised.describe(), file=sys.stderr)
        else:
            print(f"seed {seed}: not randomised (--no-randomise): the configuration as it is", file=sys.stderr)
        for plan in args.plans:
            name = f"{plan}-seed{seed}"
            code, wall = _run(config, plan, out / "runs" / name, scenario, args.duration, scale, out / "runs",
                              args.lockstep, args.record)  # fmt: skip
            record = collect(out / "runs" / name, code, finals[plan])
            record["object_home"] = object_home(config, out / "runs" / name, plan)
            record["evidence"] = run_evidence(config, plan, out / "runs" / name)
            record["success"] = record["success"] and record["object_home"] is not False
            record.update(plan=plan, seed=seed, wall_s=round(wall, 3), randomised=changed)
            if scenario is not None:
                judge(scenario, out / "runs" / name, record, config, finals[plan], plan)
            results[plan].append(record)
            print(
                f"{name}: exit {code}, {'success' if record['success'] else 'failure'}, "
                f"mission {record['mission_s']} s, wall {wall:.0f} s",
                file=sys.stderr,
            )
    plans = [summarise(plan, results[plan]) for plan in args.plans]
    result: dict[str, Any] = {
        "config": str(args.config),
        "time_scale": scale,
        "duration_s": args.duration,
        "randomised": not args.no_randomise,
        "scenario": None if scenario is None else scenario.to_dict(),
        "plans": plans,
        "results": [r for plan in args.plans for r in results[plan]],
        "plot": str(plot(plans, out / "mission-states.png")),
    }
    (out / "summary.json").write_text(json.dumps(result, indent=2))
    return result
