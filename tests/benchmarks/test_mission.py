"""``ckm-bench mission`` (issue K point 4): the randomised copies of the lab, and the runner and collector on a
tiny real plan (``configs/examples/plan_two_agents.xml``: seconds, not the lab's minutes)."""

from __future__ import annotations

import dataclasses
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from benchmarks.cli import BENCHMARKS, TAKES_OPTIONS, main
from benchmarks.mission import collect, layout_config, mission_wall, run_once, success_finals
from benchmarks.mission_random import Jitter, footprint_distance, randomise
from benchmarks.mission_report import plot, summarise, wilson
from benchmarks.mission_scenarios import BUILT_IN, judge, object_home
from plugins.sim.plan import WorldPlan
from runtime.missions.recording import Event, Run, RunRecorder, read_run
from runtime.missions.report import build_report
from runtime.verification.verify import verify_safely
from tests.conftest import CONFIGS
from tests.runtime.network.conftest import private_network

LAB = Path("configs/usecase/lab.xml")
PLAN = Path("configs/examples/plan_two_agents.xml")
Q = "{urn:ckm:1}"
OBJECTS = ("cylinder_red_stripes", "cylinder_blue_dots")  # the lab's <Randomise objects> (plan.xml)
ROBOT_RADIUS = 0.2  # the Kobuki base (0.175 m in its URDF) and 2.5 cm of margin
DEFAULT_NOISE = {"lidar": 0.01, "counter": 20.0}  # the device table's typical noise of the lab's noisy sensors


def _sim_params(copy: Path) -> list[dict[str, str]]:
    root = ET.parse(copy.parent / "nodes.xml").getroot()
    return [
        {p.get("name", ""): p.get("value", "") for p in ch.findall(Q + "Param")} | {"_kind": ch.get("kind", "")}
        for ch in root.iter(Q + "HWChannel")
        if ch.get("backend") == "sim"
    ]


def _initial_pose(copy: Path) -> str:
    root = ET.parse(copy.parent / "resources.xml").getroot()
    return next(p.get("value", "") for p in root.iter(Q + "Param") if p.get("name") == "initialPose")


def test_a_randomised_copy_is_valid_and_moves_what_it_should_by_bounded_amounts(tmp_path: Path) -> None:
    original = ckmconf.load(LAB)
    assert original.environment is not None
    before = {o.name: o for o in original.environment.objects}
    bench = before["workbench"]
    for seed in (1, 2, 3):
        done = randomise(LAB, seed, tmp_path / f"seed{seed}")
        copy = ckmconf.load(done.config)  # valid, and verified as ckm-run verifies it
        assert verify_safely(copy) == []
        assert copy.environment is not None
        after = {o.name: o for o in copy.environment.objects}
        for name, obj in after.items():
            old = before[name].pose
            if name in OBJECTS:
                assert (obj.pose.x, obj.pose.y, obj.pose.yaw) == pytest.approx(done.objects[name], abs=1e-4)
                assert abs(obj.pose.x - old.x) <= 0.03 + 1e-4 and abs(obj.pose.y - old.y) <= 0.03 + 1e-4
                assert abs(obj.pose.yaw - old.yaw) <= 0.3 + 1e-4 and obj.pose.z == old.z
                assert footprint_distance(bench, obj.pose.x, obj.pose.y) < -0.035  # on the workbench, inside its edge
                assert (obj.pose.x, obj.pose.y) != (old.x, old.y)
            else:
                assert obj.pose == old
        # the start pose: the same in every channel of the Turtlebot and in Navigation's initialPose
        assert list(done.starts) == ["turtlebot"] and list(done.kept) == ["nao"]
        start = done.starts["turtlebot"]
        x, y, yaw = start
        assert abs(x - 1.5) <= 0.15 and abs(y - 1.5) <= 0.15 and abs(yaw - 0.785) <= 0.2
        assert 0.3 + ROBOT_RADIUS <= x <= 2.6 - ROBOT_RADIUS and 0.3 + ROBOT_RADIUS <= y <= 2.6 - ROBOT_RADIUS
        assert all(footprint_distance(o, x, y) >= ROBOT_RADIUS for o in copy.environment.objects)
        channels = _sim_params(done.config)
        poses = {c["pose"] for c in channels if c.get("body") == "turtlebot" and "pose" in c}
        assert len(poses) == 1 and [float(v) for v in poses.pop().split()] == pytest.approx(start, abs=1e-4)
        assert [float(v) for v in _initial_pose(done.config).split()] == pytest.approx(start, abs=1e-4)
        nao = [c["pose"] for c in channels if c.get("body") == "nao" and "pose" in c]
        assert nao == ["7.6 6.78 -1.5708"]  # the Nao is not moved
        # noise: the lidar's and the encoders' s.d. scaled by the seed's factor; the world's seed is the seed
        assert 0.5 <= done.noise_factor <= 1.5
        for c in channels:
            base = DEFAULT_NOISE.get(c.get("sensor") or c["_kind"])
            if base is not None:
                assert float(c["noise"]) == pytest.approx(base * done.noise_factor)
            assert "seed" in c and (c["seed"] == str(seed)) == bool(c.get("world"))
        assert set(done.noise) == {"kobuki/left_encoder", "kobuki/right_encoder", "turtlebot/hokuyo"}
        plan = WorldPlan.of(list(copy.nodes))
        assert plan is not None and plan.seed == seed
        assert [float(v) for v in plan.bodies["turtlebot"][1].split()] == pytest.approx(start, abs=1e-4)


def test_the_same_seed_gives_the_same_copy_and_another_seed_another(tmp_path: Path) -> None:
    first = randomise(LAB, 7, tmp_path / "a")
    again = randomise(LAB, 7, tmp_path / "b")
    other = randomise(LAB, 8, tmp_path / "c")
    assert first.to_json() == again.to_json() != other.to_json()
    for name in ("nodes.xml", "resources.xml", "environment.xml"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    quiet = randomise(LAB, 7, tmp_path / "d", noise_scale=0.0)
    assert quiet.noise_factor == 0.0 and all(v == 0.0 for v in quiet.noise.values())
    assert quiet.objects == first.objects and quiet.starts == first.starts  # the same draws, the noise aside
    assert randomise(LAB, 7, tmp_path / "e", Jitter(noise_scale=0.0)).to_json() == quiet.to_json()  # the lab's own


def test_the_randomised_world_holds_the_objects_on_the_table_and_the_robot_clear(tmp_path: Path) -> None:
    done = randomise(LAB, 5, tmp_path / "seed5")
    plan = WorldPlan.of(list(ckmconf.load(done.config).nodes))
    assert plan is not None
    sim = plan.build()
    try:
        sim.world.run_until(1.0)  # one simulated second of physics: nothing falls, nothing is pushed
        where = sim.world.movable_positions()
        for name in OBJECTS:
            x, y, z = where[name]
            assert math.hypot(x - done.objects[name][0], y - done.objects[name][1]) < 0.005
            assert z > 0.30
        start = done.starts["turtlebot"]
        assert math.hypot(where["turtlebot"][0] - start[0], where["turtlebot"][1] - start[1]) < 0.02
    finally:
        sim.world.close()


def test_wilson_interval_matches_its_formula_at_known_points() -> None:
    assert wilson(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert wilson(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert wilson(0, 0) == (0.0, 1.0)


def test_bench_runs_a_plan_and_its_summary_is_what_the_recordings_say(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert "mission" in BENCHMARKS and "mission" in TAKES_OPTIONS
    out = tmp_path / "bench"
    argv = ["mission", "--json", "--config", str(PLAN), "--plans", "fetch-together", "--runs", "2"]
    argv += ["--duration", "30", "--time-scale", "0", "--no-randomise", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr()
    assert "seed 2: not randomised (--no-randomise)" in printed.err
    result = json.loads(printed.out.strip().splitlines()[-1])
    assert json.loads((out / "summary.json").read_text()) == result
    (plan,) = result["plans"]
    assert set(plan) >= {"plan", "runs", "success_rate", "mean_mission_s", "realtime_factor", "states"}
    assert plan["plan"] == "fetch-together" and plan["runs"] == 2 and plan["success_rate"] == 1.0
    assert plan["success_ci95"] == pytest.approx(wilson(2, 2), abs=1e-4)
    assert [r["seed"] for r in result["results"]] == [1, 2]
    missions: list[float] = []
    times: dict[str, list[float]] = {}
    for record in result["results"]:
        assert record["exit_code"] == 0 and record["success"]
        assert record["outcomes"] == {"walker": "over", "carrier": "done"}
        recorded = read_run(Path(record["run_dir"]))
        begin = min(a.begin for a in recorded.agents.values())
        missions.append(max(a.finish for a in recorded.agents.values()) - begin)
        assert record["mission_s"] == pytest.approx(missions[-1], abs=1e-5)
        for agent in build_report(recorded).agents:
            for row in agent.rows:
                times.setdefault(f"{agent.agent}: {row.label}", []).append(row.time)
        assert (out / "runs" / f"fetch-together-seed{record['seed']}.log").read_text().startswith("$ ")
    assert plan["mean_mission_s"] == pytest.approx(sum(missions) / 2, abs=1e-5)
    assert 2.5 < plan["mean_mission_s"] < 30  # LOOK 1 s + TRACK 1.5 s, then APPR 2 s
    assert [s["name"] for s in plan["states"]] == list(times)
    walker = {"walker: SEARCH/LOOK", "walker: SEARCH/TRACK", "walker: SEARCH/REPORT"}
    assert set(times) == walker | {"carrier: WAIT", "carrier: APPR"}
    for state in plan["states"]:
        assert state["runs"] == 2 and state["times_s"] == pytest.approx(times[state["name"]], abs=1e-5)
        assert state["mean_s"] == pytest.approx(sum(times[state["name"]]) / 2, abs=1e-5)
        assert set(state) >= {"name", "mean_s", "contribution", "avg_performance"} and 0 < state["contribution"] <= 1
    look = next(s for s in plan["states"] if s["name"] == "walker: SEARCH/LOOK")
    assert look["mean_s"] == pytest.approx(1.0, abs=0.3)  # the timer behavior's duration
    assert 0 < plan["realtime_factor"] <= 1.0
    # the mission alone (D248): from the first start to the last end on the machine's clock, no start-up
    assert all(0 < r["mission_wall_s"] < r["wall_s"] for r in result["results"])
    phase = sum(r["mission_wall_s"] for r in result["results"])
    assert plan["mission_realtime_factor"] == pytest.approx(sum(missions) / phase, rel=1e-3)
    assert plan["mission_realtime_factor"] > plan["realtime_factor"]
    assert (out / "mission-states.png").stat().st_size > 5_000


SIGNAL = "/plan/fetch-together/object-spotted"


def test_a_lockstep_bench_runs_without_the_default_time_scale(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # ckm-run refuses --lockstep beside --time-scale: the bench must not pass its default scale along
    out = tmp_path / "bench"
    argv = ["mission", "--json", "--config", str(PLAN), "--plans", "fetch-together", "--runs", "1"]
    argv += ["--duration", "30", "--lockstep", "0.01", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr()
    result = json.loads(printed.out.strip().splitlines()[-1])
    assert result["time_scale"] is None and result["plans"][0]["success_rate"] == 1.0
    # a plan with no environment and no simulated robot: randomised, and the line says that nothing moved (D301)
    assert "seed 1: objects moved: none; starts moved: none; noise none (no noisy sensor)" in printed.err
    assert result["randomised"] and result["results"][0]["randomised"]["objects"] == {}
    command = (out / "runs" / "fetch-together-seed1.log").read_text().splitlines()[0]
    assert "--lockstep 0.01" in command and "--time-scale" not in command


def test_record_reaches_every_run_s_ckm_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the plan-only system has no topic: ckm-run's own refusal shows the option got there
    out = tmp_path / "bench"
    argv = ["mission", "--json", "--config", str(PLAN), "--plans", "fetch-together", "--runs", "1"]
    argv += ["--duration", "30", "--lockstep", "0.01", "--no-randomise", "--out", str(out), "--record", SIGNAL]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["plans"][0]["success_rate"] == 0.0
    command, *rest = (out / "runs" / "fetch-together-seed1.log").read_text().splitlines()
    assert command.endswith(f"--record {SIGNAL}")
    assert f"--record: no topic '{SIGNAL}' here" in "\n".join(rest)


def test_a_run_stopped_at_its_timeout_or_failing_is_no_success(tmp_path: Path) -> None:
    finals = success_finals(PLAN, "fetch-together")
    assert finals == {"walker": "over", "carrier": "done"}
    run_dir = tmp_path / "run"
    code, wall = run_once(PLAN, "fetch-together", run_dir, duration=30, time_scale=None, log=tmp_path / "run.log",
                          timeout=0.5)  # fmt: skip
    assert code is None and wall < 60
    assert "timed out" in (tmp_path / "run.log").read_text()
    record = collect(run_dir, code, finals)
    assert not record["success"]
    code, _ = run_once(PLAN, "fetch-together", tmp_path / "ok", duration=30, time_scale=None, log=tmp_path / "ok.log")
    assert code == 0 and collect(tmp_path / "ok", code, finals)["success"]
    assert not collect(tmp_path / "ok", 1, finals)["success"]  # every agent ended well, but ckm-run did not exit 0
    assert not collect(tmp_path / "ok", 0, {**finals, "walker": "gave-up"})["success"]
    summary = summarise("p", [collect(tmp_path / "ok", 1, finals) | {"wall_s": 5.0}])
    assert summary["success_rate"] == 0.0 and summary["mean_mission_s"] is None and summary["states_from"] == "all"
    empty = collect(tmp_path / "nowhere", None, finals)
    assert empty["mission_s"] is None and "no such run directory" in empty["error"]


def test_an_unknown_plan_is_refused_before_anything_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as refused:
        main(["mission", "--config", str(PLAN), "--plans", "nope", "--out", str(tmp_path)])
    assert refused.value.code == 2 and "no plan 'nope' (plans: fetch-together)" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def _network_ports(copy: Path) -> dict[str, str]:
    network = ET.parse(copy.parent / "network.xml").getroot().find(Q + "Network")
    assert network is not None
    return {k: network.get(k, "") for k in ("discoveryPort", "basePort")}


@pytest.mark.parametrize("layout", ["lab", "compact"])
def test_the_ports_option_gives_the_copys_network_its_ports(tmp_path: Path, layout: str) -> None:
    """``--ports`` (a bench beside another on one machine): the copy the runs start from has them in network.xml."""
    copy = layout_config(LAB, layout, tmp_path, (7851, 7861))
    assert copy.parent.parent == tmp_path / "configs" and copy.name == LAB.name
    assert _network_ports(copy) == {"discoveryPort": "7851", "basePort": "7861"}
    network = ckmconf.load(copy).network
    assert network is not None and (network.discovery_port, network.base_port) == (7851, 7861)
    assert _network_ports(LAB) == {"discoveryPort": "7400", "basePort": "7410"}  # the lab itself is left alone
    # the randomised copies are made from it, so every run of the bench is on those ports
    assert _network_ports(randomise(copy, 3, tmp_path / "seed3").config) == _network_ports(copy)
    assert layout_config(LAB, "lab", tmp_path) == LAB  # no ports, no copy


@pytest.mark.parametrize(
    ("config", "ports", "message"),
    [
        (LAB, ["7851", "7851"], "--ports must be two different ports in 1024-65535, not 7851 7851"),
        (LAB, ["80", "7861"], "--ports must be two different ports in 1024-65535, not 80 7861"),
        (PLAN, ["7851", "7861"], "plan_two_agents.xml: no <Network> to give the ports 7851 7861"),
    ],
)
def test_bad_ports_are_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], config: Path, ports: list[str], message: str
) -> None:
    plan = "individual" if config == LAB else "fetch-together"
    with pytest.raises(SystemExit) as refused:
        main(["mission", "--config", str(config), "--plans", plan, "--ports", *ports, "--out", str(tmp_path)])
    assert refused.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def _record_lab_like_run(run_dir: Path, nav: float, spot: float) -> None:
    """A recording of the individual mission's shape (Fig. 7.12), written as the engine writes it."""
    now = [0.0]
    with RunRecorder(run_dir, "turtlebot", clock=lambda: now[0], wall_clock=lambda: 1e9 + now[0]) as rec:
        rec.write("start", mission="Agent1Fetch", plan="individual")
        steps = [
            ("Agent1Fetch/INIT", None, 1.0),
            ("Agent1Fetch/Navigation/NAV", "Navigation", nav),
            ("Agent1Fetch/ObjectInteraction/SPOT", "ObjectInteraction", spot),
            ("Agent1Fetch/ObjectInteraction/APPR", "ObjectInteraction", 4.0),
            ("Agent1Fetch/ObjectInteraction/PICK", "ObjectInteraction", 6.0),
            ("Agent1Fetch/ObjectPlace/NAV", "ObjectPlace", nav / 2),
        ]
        for path, nested, seconds in steps:
            if nested is not None and path.count("/") == 2:
                rec.write("enter", path=f"Agent1Fetch/{nested}", state=nested, nested=nested)
            rec.write("enter", path=path, state=path.rsplit("/", 1)[-1], nested=None)
            rec.write("progress", path=path, progress=0.5, performance=0.8, mission_progress=0.5)
            now[0] += seconds
            rec.write("exit", path=path, state=path.rsplit("/", 1)[-1], to="next", reason="transition")
            if nested is not None:
                rec.write("exit", path=f"Agent1Fetch/{nested}", state=nested, to="next", reason="transition")
        rec.write("end", outcome="succeeded")


def test_the_lab_missions_rows_are_set_next_to_table_7_9(tmp_path: Path) -> None:
    finals = success_finals(LAB, "individual")
    assert finals == {"turtlebot": "succeeded"}
    assert success_finals(LAB, "cooperative") == {"turtlebot": "succeeded", "nao": "spotted"}
    records = []
    for k, (nav, spot) in enumerate(((20.0, 3.0), (30.0, 5.0))):
        _record_lab_like_run(tmp_path / f"r{k}", nav, spot)
        records.append(collect(tmp_path / f"r{k}", 0, finals) | {"wall_s": 100.0})
    assert all(r["success"] for r in records)
    assert records[0]["thesis"] == pytest.approx({"NAVIGATION": 30.0, "SPOT": 3.0, "APPR-PICK": 10.0})
    assert records[0]["mission_s"] == pytest.approx(1 + 20 + 3 + 4 + 6 + 10)
    summary = summarise("individual", records)
    thesis = {t["state"]: t for t in summary["thesis"]}
    assert thesis["NAVIGATION"]["mean_s"] == pytest.approx((30 + 45) / 2) and thesis["NAVIGATION"]["runs"] == 2
    assert thesis["NAVIGATION"]["thesis_s"] == pytest.approx(56.676 + 52.856, abs=1e-3)
    assert thesis["SPOT"]["mean_s"] == pytest.approx(4.0) and thesis["SPOT"]["thesis_s"] == pytest.approx(18.651)
    spot = next(s for s in summary["states"] if s["name"] == "turtlebot: ObjectInteraction/SPOT")
    assert spot["times_s"] == pytest.approx([3.0, 5.0]) and spot["avg_performance"] == pytest.approx(0.8)
    assert spot["contribution"] == pytest.approx((3 / 44 + 5 / 61) / 2, abs=1e-5)
    assert summary["realtime_factor"] == pytest.approx((44 + 61) / 200)


# ---------------------------------------------------------------------- --scenario (issue K point 3, D179)

ROVER = Path("tests/data/plans/disturbed_rover.xml")  # a sim lidar: ckm-run starts a world server
LOST = Path("tests/data/plans/lost_spotter.xml")  # the fetcher takes its failure branch on lost('spotter')


def _on_private_network(config: Path, tmp_path: Path) -> Path:
    """``config`` on a private loopback network: a split run's processes talk over it."""
    system = ckmconf.load(config)
    path = tmp_path / config.name
    ckmconf.dump(dataclasses.replace(system, network=private_network()), path)
    return path


def _bench(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[dict[str, Any], str]:
    assert main(["mission", "--json", "--runs", "1", "--time-scale", "0", "--no-randomise", *argv]) == 0
    printed = capsys.readouterr().out
    return json.loads(printed.strip().splitlines()[-1]), printed


def test_a_world_scenario_reaches_the_runs_world_server_and_is_named_in_the_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = tmp_path / "crate.scenario"
    scenario.write_text("at 0.3 add box crate 0.4 0.4 0.4 beside rover 1.0 0\n")
    out = tmp_path / "bench"
    argv = ["--config", str(ROVER), "--plans", "alone", "--duration", "20", "--scenario", str(scenario)]
    result, printed = _bench([*argv, "--out", str(out)], capsys)
    assert result["scenario"] == {"name": "crate", "world": str(scenario), "kill_agent": None, "kill_after": 5.0,
                                  "expect": "success"}  # fmt: skip
    (record,) = result["results"]
    assert record["success"] and record["scenario"] == "crate" and record["killed"] is None
    assert [(f["body"], f["line"]) for f in record["disturbances"]] == [("crate", 1)]
    assert record["disturbed"] and record["handled"] and record["object_home"] is None  # no drop table here
    run_dir = Path(record["run_dir"])
    assert json.loads((run_dir / "sim-disturbances.json").read_text()) == record["disturbances"]
    assert json.loads((run_dir / "scenario.json").read_text())["scenario"]["name"] == "crate"
    (plan,) = result["plans"]
    assert (plan["disturbed"], plan["handled"]) == (1, 1)
    assert "crate (expects success)" in printed and "1/1 disturbed runs" in printed


def test_a_killed_agent_is_reported_lost_and_the_other_takes_its_failure_branch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = _on_private_network(LOST, tmp_path)
    out = tmp_path / "bench"
    argv = ["--config", str(config), "--plans", "together", "--duration", "30", "--scenario", "lost-humanoid"]
    result, printed = _bench([*argv, "--kill-agent", "spotter", "--kill-after", "0.5", "--out", str(out)], capsys)
    (record,) = result["results"]
    assert record["killed"]["agent"] == "spotter" and record["killed"]["node"] == "spotter-pc"
    assert record["outcomes"]["fetcher"] == "failed" and not record["success"]
    assert record["lost_reported"] == ["fetcher"] and record["handled"]
    assert result["scenario"]["name"] == "lost-humanoid" and result["scenario"]["expect"] == "failure"
    assert "lost-humanoid (expects failure, kills agent spotter 0.5 s in)" in printed
    logs = sorted(p.name for p in (out / "runs").glob("together-seed1.*.log"))
    assert logs == ["together-seed1.fetcher-pc.log", "together-seed1.spotter-pc.log"]


def test_the_examples_carrier_does_not_handle_a_lost_walker(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """plan_two_agents' carrier has no lost() branch: it waits on, and the bench says it did not cope."""
    config = _on_private_network(PLAN, tmp_path)
    argv = ["--config", str(config), "--plans", "fetch-together", "--duration", "8", "--kill-agent", "walker"]
    result, _ = _bench([*argv, "--kill-after", "0.3", "--out", str(tmp_path / "bench")], capsys)
    (record,) = result["results"]
    assert record["killed"]["agent"] == "walker" and record["lost_reported"] == ["carrier"]
    assert record["outcomes"]["carrier"] == "stopped" and not record["handled"]
    assert result["plans"][0]["handled"] == 0 and result["plans"][0]["disturbed"] == 1


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "blocked-path"], "disturbs the simulated world, but"),
        (["--scenario", "nope"], "no scenario 'nope' (scenarios: blocked-path, moved-object, dropped-object, lost"),
        (["--kill-agent", "nobody"], "plan fetch-together has no agent 'nobody' (agents: walker, carrier)"),
        (["--kill-after", "2"], "--kill-after goes with --kill-agent"),
        (["--kill-agent", "walker", "--record", SIGNAL], "--record cannot record a split run"),
        (["--scenario", "moved-object", "--kill-after", "2"], "scenario 'moved-object' kills no agent"),
    ],
)
def test_a_scenario_that_cannot_apply_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    with pytest.raises(SystemExit):
        main(["mission", "--config", str(PLAN), "--plans", "fetch-together", "--out", str(tmp_path), *args])
    assert message in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_a_world_scenario_naming_a_body_the_world_lacks_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = tmp_path / "boulder.scenario"
    scenario.write_text("# the rover's world has no boulder\nat 1 remove boulder\n")
    with pytest.raises(SystemExit):
        main(
            ["mission", "--config", str(ROVER), "--plans", "alone", "--scenario", str(scenario), "--out", str(tmp_path)]
        )
    assert f"{scenario}:2:13: no body 'boulder' in the world (bodies: rover)" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_a_split_run_shares_one_world_server_on_the_runs_clock(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The lab's lost-humanoid in small: the rover's node (a sim lidar) and the spotter's run as two
    processes on one world server the bench started, all at --time-scale 0.5; the spotter is killed."""
    config = _on_private_network(ROVER, tmp_path)
    argv = ["--config", str(config), "--plans", "together", "--duration", "40", "--kill-agent", "spotter"]
    argv += ["--kill-after", "0.5", "--out", str(tmp_path / "bench")]
    assert main(["mission", "--json", "--runs", "1", "--time-scale", "0.5", "--no-randomise", *argv]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    (record,) = result["results"]
    assert record["outcomes"]["rover"] == "gave_up" and record["lost_reported"] == ["rover"] and record["handled"]
    run_dir = Path(record["run_dir"])
    assert sorted(p.name for p in run_dir.glob("sim-server*.json")) == ["sim-server.json"]  # one world, the bench's
    final = json.loads((run_dir / "sim-final.json").read_text())
    assert 0 < final["time"] < 0.75 * record["wall_s"]  # the world's clock ran at the run's scale (0.5)
    gave_up = next(e for e in read_run(run_dir).events if e.kind == "exit" and e.fields["state"] == "NAV")
    assert gave_up.fields["to"] == "gave_up" and gave_up.t < 20  # lost after 1.5 s, not NAV's 60 s timeout


def test_a_disturbed_run_whose_ckm_run_made_no_directory_is_judged_a_failure(tmp_path: Path) -> None:
    # ckm-run refused its arguments (a bad --record topic) before making the run directory
    run_dir = tmp_path / "runs" / "cooperative-seed1"
    record = collect(run_dir, 2, {"turtlebot": "succeeded"})
    lab = CONFIGS / "usecase" / "lab.xml"
    judge(BUILT_IN["blocked-path"], run_dir, record, lab, {"turtlebot": "succeeded"}, "individual")
    assert record["handled"] is False and record["disturbed"] is False
    assert json.loads((run_dir / "scenario.json").read_text())["scenario"]["name"] == "blocked-path"


def test_the_mission_phase_is_unknown_while_an_agent_that_started_has_no_end(tmp_path: Path) -> None:
    def event(agent: str, kind: str, real: float) -> Event:
        return Event(t=real, agent=agent, kind=kind, fields={"real": real}, local_t=real, source="x:1")

    both = [event("a", "start", 10.0), event("b", "start", 11.0), event("a", "end", 40.0), event("b", "end", 42.5)]
    assert mission_wall(Run(tmp_path, both)) == 32.5  # first start to last end
    assert mission_wall(Run(tmp_path, both[:3])) is None  # b started and was cut off: no phase
    assert mission_wall(Run(tmp_path, both[:2])) is None


@pytest.mark.parametrize(
    ("where", "home"),
    [
        ((1.02, 1.75, 0.36), True),  # standing on the drop table's 0.30 m top
        ((0.95, 1.80, 0.335), True),  # lying on it
        ((1.0, 1.45, 0.06), False),  # on the floor in front of it, within the 0.5 m radius
        ((2.0, 1.9, 0.36), False),  # at the table's height, a metre away
        ((1.0, 1.9), False),  # a final state with no height
    ],
)
def test_the_object_is_home_only_on_the_drop_table_s_top(tmp_path: Path, where: tuple[float, ...], home: bool) -> None:
    """object_home (the bench's check that the robots did the work): compact seed 301 once left the
    cylinder on the floor 0.3 m in front of the table and was counted home by the radius alone."""
    (tmp_path / "sim-final.json").write_text(json.dumps({"positions": {"cylinder_red_stripes": list(where)}}))
    assert object_home(CONFIGS / "usecase" / "lab.xml", tmp_path, "cooperative") is home
    (tmp_path / "sim-final.json").write_text(json.dumps({"positions": {}}))
    assert object_home(CONFIGS / "usecase" / "lab.xml", tmp_path, "cooperative") is None


def test_the_state_plot_of_runs_that_recorded_no_state_says_so_without_warnings(tmp_path: Path) -> None:
    """Every run failed before its first state (a broken configuration, say): the plot is still made,
    with a line saying why it is empty, and matplotlib warns of nothing (no singular axis, no empty legend)."""
    import warnings

    plans = [{"plan": "cooperative", "states_from": "all", "states": []}]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        made = plot(plans, tmp_path / "states.png")
    assert made.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
