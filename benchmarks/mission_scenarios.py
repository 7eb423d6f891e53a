"""``ckm-bench mission --scenario NAME``: the failures of issue K point 3 caused on purpose (§7.3–7.5, D179).

A scenario disturbs every run of the benchmark and says how the missions must handle it:

- ``blocked-path``, ``moved-object``, ``dropped-object``: a world scenario file
  (``benchmarks/scenarios/NAME.scenario``, :mod:`plugins.sim.scenario`) the run's world server
  fires (``CKM_SIM_SCENARIO``); expected: the mission still succeeds (re-plan, spot again, pick
  again) and the object ends on the drop table (the world's own evidence, ``sim-final.json``);
- ``lost-humanoid``: the process of the plan's agent ``nao`` is killed (SIGKILL) 1 simulated
  second after its mission started, before the Nao signals (D232); expected: every other agent
  ends in a failure final (the Turtlebot's ``lost('nao')`` branch) and its recording has
  ``agent-lost``.

``--scenario FILE.scenario`` runs any world scenario file (expected: success); ``--kill-agent`` and
``--kill-after`` set or change the killed agent and the delay. A world scenario needs a
configuration with ``hardware.sim`` channels.

A run with a killed agent is *split*: one ``ckm-run --node N`` per node of the system, in a process
group of its own (the victim is its agent's node), sharing one world server (started here, when
the configuration has sim channels) and one clock origin (``runtime.simtime``); the nodes that run
no agent are stopped (SIGINT) once every surviving agent's process has ended. Every run keeps
``RUN/scenario.json`` (the scenario, the kill: agent, node, pid, wall time) and the record of
:func:`judge` (disturbed, handled, object_home) goes into the benchmark's summary and table.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import ckmconf
from benchmarks.mission_placement import _inside
from ckmconf.model.environment import EnvObject, Geometry3D, Geometry25D
from plugins.sim.disturbances import ENV_SCENARIO, Disturbances
from plugins.sim.plan import WorldPlan
from plugins.sim.scenario import ScenarioError, read
from runtime import simtime
from runtime.missions.recording import RunError, agent_file_name, read_run

SCENARIOS = Path(__file__).with_name("scenarios")
STOP_GRACE_S = 30.0


@dataclass(frozen=True)
class Scenario:
    """A benchmark scenario: a world scenario file and/or an agent to kill, and what must follow."""

    name: str
    world: str | None = None
    kill_agent: str | None = None
    kill_after: float = 5.0
    expect: str = "success"  # "success": the missions cope; "failure": the others take their failure branch

    def to_dict(self) -> dict[str, Any]:
        """The scenario as the run and the summary keep it."""
        return asdict(self)


BUILT_IN = {
    "blocked-path": Scenario("blocked-path", world=str(SCENARIOS / "blocked-path.scenario")),
    "moved-object": Scenario("moved-object", world=str(SCENARIOS / "moved-object.scenario")),
    "dropped-object": Scenario("dropped-object", world=str(SCENARIOS / "dropped-object.scenario")),
    "lost-humanoid": Scenario("lost-humanoid", kill_agent="nao", kill_after=1.0, expect="failure"),  # D232,
}


def choose(name: str | None, kill_agent: str | None, kill_after: float | None) -> Scenario | None:
    """The scenario of the command line; ValueError naming what is wrong (an unknown name, a bad file)."""
    if name is None and kill_agent is None:
        if kill_after is not None:
            raise ValueError("--kill-after goes with --kill-agent or a scenario that kills one")
        return None
    if name is None:
        scenario = Scenario("lost-agent", expect="failure")
    elif name in BUILT_IN:
        scenario = BUILT_IN[name]
    elif name.endswith(".scenario"):
        scenario = Scenario(Path(name).stem, world=name)
    else:
        raise ValueError(f"no scenario {name!r} (scenarios: {', '.join(BUILT_IN)}, or a FILE.scenario)")
    if kill_agent is not None:
        scenario = replace(scenario, kill_agent=kill_agent, expect="failure")
    if kill_after is not None:
        if kill_after < 0:
            raise ValueError(f"--kill-after must not be negative, not {kill_after:g}")
        if scenario.kill_agent is None:
            raise ValueError(f"--kill-after: scenario {scenario.name!r} kills no agent (add --kill-agent)")
        scenario = replace(scenario, kill_after=kill_after)
    if scenario.world is not None:
        try:
            read(scenario.world)  # its syntax now; its names when the world is built
        except ScenarioError as error:
            raise ValueError(str(error)) from None
    return scenario


def check(scenario: Scenario, config: Path, plans: list[str]) -> None:
    """ValueError if ``scenario`` cannot apply to ``config`` (no simulated world, a body it does not
    have, no such agent)."""
    system = ckmconf.load(config)
    if scenario.world is not None:
        world = WorldPlan.of(list(system.nodes))
        if world is None:
            raise ValueError(f"scenario {scenario.name} disturbs the simulated world, but {config} has no "
                             "hardware.sim channel")  # fmt: skip
        sim = world.build()  # its names, against the world every run will build (FILE:LINE:COL)
        try:
            Disturbances(read(scenario.world)).install(sim.world)
        except ScenarioError as error:
            raise ValueError(str(error)) from None
        finally:
            sim.world.close()
    if scenario.kill_agent is not None:
        for name in plans:
            plan = system.plan(name)
            if plan is not None and all(a.name != scenario.kill_agent for a in plan.agents):
                agents = ", ".join(a.name for a in plan.agents)
                raise ValueError(f"scenario {scenario.name}: plan {name} has no agent {scenario.kill_agent!r} "
                                 f"(agents: {agents})")  # fmt: skip


def environment(scenario: Scenario | None) -> dict[str, str]:
    """The variables a run's processes get: the world scenario for its world server."""
    return {} if scenario is None or scenario.world is None else {ENV_SCENARIO: str(Path(scenario.world).resolve())}


def _started(run_dir: Path, agent: str) -> bool:
    try:
        return '"kind":"start"' in (run_dir / agent_file_name(agent)).read_text()
    except OSError:
        return False


@contextlib.contextmanager
def _environ(extra: dict[str, str]) -> Iterator[None]:
    """``extra`` in this process's environment while the block runs (a child started there inherits it)."""
    saved = {name: os.environ.get(name) for name in extra}
    os.environ.update(extra)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _stop(process: subprocess.Popen[bytes], sig: int = signal.SIGINT) -> None:
    try:
        os.killpg(process.pid, sig)
        try:
            process.wait(timeout=STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.wait()


def run_split(
    config: Path, plan: str, run_dir: Path, scenario: Scenario, *, duration: float, time_scale: float | None,
    log: Path, timeout: float,
) -> int | None:  # fmt: skip
    """One run split over a ``ckm-run --node`` per node, the scenario's agent killed; the exit code
    (the worst of the agents' processes; None when one outlived ``timeout`` wall seconds)."""
    from plugins.sim.session import ServerProcess  # here: only a split run needs it

    system = ckmconf.load(config)
    record = system.plan(plan)
    assert record is not None and scenario.kill_agent is not None
    victim = next(a.node for a in record.agents if a.name == scenario.kill_agent)
    agent_nodes = {a.node for a in record.agents}
    env = {**os.environ, **environment(scenario)}
    if time_scale is not None:  # one clock origin for every process of the run
        env.update(simtime.environment(time_scale))
    run_dir.mkdir(parents=True, exist_ok=True)
    kept: dict[str, Any] = {"scenario": scenario.to_dict(), "plan": plan, "split": True, "killed": None}
    server = None
    if WorldPlan.of(list(system.nodes)) is not None:
        options = ["--scenario", env[ENV_SCENARIO]] if ENV_SCENARIO in env else []
        with _environ({k: v for k, v in env.items() if k in (simtime.SCALE_VARIABLE, simtime.ORIGIN_VARIABLE)}):
            server = ServerProcess(config, run_dir, options=options)  # on the run's clock, as the nodes
        env.update(server.environ())
    processes: dict[str, subprocess.Popen[bytes]] = {}
    started = time.monotonic()
    code: int | None = 0
    try:
        for node in system.nodes:
            command = [sys.executable, "-m", "runtime.cli", str(config), "--node", node.name, "--plan", plan,
                       "--duration", f"{duration:g}", "--log-dir", str(run_dir)]  # fmt: skip
            if time_scale is not None:
                command += ["--time-scale", f"{time_scale:g}"]
            out = log.with_name(f"{log.stem}.{node.name}.log").open("w")
            out.write("$ " + " ".join(command) + "\n")
            out.flush()
            processes[node.name] = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, env=env,
                                                    start_new_session=True)  # fmt: skip
            out.close()
        while not _started(run_dir, scenario.kill_agent) and time.monotonic() - started < timeout:
            if processes[victim].poll() is not None:
                break
            time.sleep(0.1)
        time.sleep(scenario.kill_after / (time_scale or 1.0))
        if processes[victim].poll() is None:
            os.killpg(processes[victim].pid, signal.SIGKILL)
            kept["killed"] = {"agent": scenario.kill_agent, "node": victim, "pid": processes[victim].pid,
                              "wall": time.time(), "after_start_s": scenario.kill_after}  # fmt: skip
        processes[victim].wait()
        for name, process in processes.items():
            if name == victim or name not in agent_nodes:
                continue
            try:
                returned = process.wait(timeout=max(1.0, timeout - (time.monotonic() - started)))
                code = None if code is None else max(code, returned)
            except subprocess.TimeoutExpired:
                code = None
    finally:
        for process in processes.values():
            if process.poll() is None:
                _stop(process)
        if server is not None:
            server.stop()
        (run_dir / "scenario.json").write_text(json.dumps(kept, indent=1))
    return code


def judge(
    scenario: Scenario, run_dir: Path, record: dict[str, Any], config: Path, finals: dict[str, str], plan: str
) -> None:
    """Add to a run's ``record`` what the scenario did and whether the missions handled it."""
    fired: list[dict[str, Any]] = []
    with contextlib.suppress(OSError, ValueError):
        fired = json.loads((run_dir / "sim-disturbances.json").read_text())
    killed = None
    with contextlib.suppress(OSError, ValueError):
        killed = json.loads((run_dir / "scenario.json").read_text()).get("killed")
    if scenario.kill_agent is None:
        run_dir.mkdir(parents=True, exist_ok=True)  # a ckm-run that refused its arguments made none
        (run_dir / "scenario.json").write_text(json.dumps({"scenario": scenario.to_dict(), "split": False}, indent=1))
    record["scenario"] = scenario.name
    record["disturbances"] = fired
    record["killed"] = killed
    record["disturbed"] = bool(fired) or killed is not None
    record["object_home"] = object_home(config, run_dir, plan)
    record["evidence"] = run_evidence(config, plan, run_dir)
    if scenario.expect == "success":
        record["handled"] = bool(record["success"]) and record["object_home"] is not False
    else:
        survivors = {a: f for a, f in finals.items() if a != scenario.kill_agent}
        outcomes = record["outcomes"]
        try:
            events = read_run(run_dir).events
        except RunError:
            events = []
        record["lost_reported"] = sorted({e.agent for e in events if e.kind == "agent-lost"
                                          and e.fields.get("lost") == scenario.kill_agent})  # fmt: skip
        record["handled"] = bool(killed is not None and record["lost_reported"] and all(
            outcomes.get(a) not in (None, "stopped", "crashed", f) for a, f in survivors.items()
        ))  # fmt: skip


def evidence(config: Path, plan: str, final: dict[str, Any]) -> list[dict[str, Any]]:
    """Each ``<Expect>`` of ``plan`` (D300) judged against a world's final record (``sim-final.json``):
    ``{object, on, in, met, position}``; ``met`` is None when the record lacks the object. An expected
    robot (D306) is judged by its base's final position (``bodies``)."""
    system = ckmconf.load(config)
    found = system.plan(plan)
    environment = system.environment
    if found is None or environment is None:
        return []
    objects = {o.name: o for o in environment.objects}
    areas = {a.name: a.points() for a in environment.areas}
    out: list[dict[str, Any]] = []
    for expect in found.expects:
        position = final.get("positions", {}).get(expect.object)
        if position is None and expect.object in final.get("bodies", {}):  # a robot (D306): its base's x, y, z
            position = final["bodies"][expect.object][:3]
        met: bool | None = None
        if position is not None:
            met = True
            place = objects.get(expect.on) if expect.on is not None else None
            if place is not None:
                near = math.hypot(position[0] - place.pose.x, position[1] - place.pose.y) <= expect.within
                met = bool(near and len(position) > 2 and position[2] > _top(place))  # on top, not beside
            if expect.in_ is not None:
                met = met and _inside(areas.get(expect.in_, []), position[0], position[1])
        out.append({"object": expect.object, "on": expect.on, "in": expect.in_, "met": met,
                    "position": position})  # fmt: skip
    return out


def run_evidence(config: Path, plan: str, run_dir: Path) -> list[dict[str, Any]] | None:
    """:func:`evidence` of a run's ``sim-final.json`` (None: the run left no final record)."""
    try:
        final = json.loads(next(iter(sorted(run_dir.glob("sim-final*.json")))).read_text())
    except (StopIteration, OSError, ValueError):
        return None
    return evidence(config, plan, final)


def object_home(config: Path, run_dir: Path, plan: str) -> bool | None:
    """Whether every ``<Expect>`` of ``plan`` is met by the run's final world (None: not known)."""
    judged = run_evidence(config, plan, run_dir)
    if not judged or any(e["met"] is None for e in judged):
        return None
    return all(e["met"] for e in judged)


def _top(place: EnvObject) -> float:
    """The height of an environment object's highest face (m): its pose's z plus its prisms' zmax."""
    geometry = place.geometry
    prisms = (
        geometry.prisms
        if isinstance(geometry, Geometry3D)
        else ((geometry.prism,) if isinstance(geometry, Geometry25D) else ())
    )
    return place.pose.z + max((prism.zmax for prism in prisms), default=0.0)
