"""``ckm-bench mission``'s randomised copies of any configuration (benchmarks/mission_random.py, D301): the
aerial example (two UAVs on pads), the bring-your-own-robot scout (a user URDF), a station arm beside a
rover, and what ``<Validation><Randomise>`` declares. The lab's own copies: tests/benchmarks/test_mission.py."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import ckmconf
from benchmarks.mission_bodies import bodies
from benchmarks.mission_placement import footprint_distance, is_marking, movable, radius
from benchmarks.mission_random import START_MARGIN, randomise
from plugins.sim.plan import WorldPlan
from runtime.verification.verify import verify_safely
from tests.conftest import CONFIGS

AERIAL = CONFIGS / "examples" / "aerial" / "uavs.xml"
BYOR = CONFIGS / "examples" / "byor" / "scout.xml"
STATION = CONFIGS / "examples" / "sim_station.xml"
LAB = CONFIGS / "usecase" / "lab.xml"
Q = "{urn:ckm:1}"


def _params(path: Path) -> list[dict[str, str]]:
    """Every element's direct ``<Param>``s of ``path``, for the elements that have some."""
    found = []
    for element in ET.parse(path).getroot().iter():
        params = {p.get("name", ""): p.get("value", "") for p in element.findall(Q + "Param")}
        if params:
            found.append(params | {"_name": element.get("name", ""), "_tag": element.tag.removeprefix(Q)})
    return found


def _poses(system: ckmconf.model.System) -> dict[str, str]:
    """body → its ``pose`` Param, from the sim channels."""
    out = {}
    for node in system.nodes:
        for channel in node.channels:
            values = {p.name: p.value for p in channel.params}
            if channel.backend == "sim" and values.get("pose"):
                out[values["body"]] = values["pose"]
    return out


def test_the_bodies_are_mobile_when_they_drive_a_wheel_or_fly() -> None:
    found = {cfg.name: {b.name: b for b in bodies(ckmconf.load(cfg))} for cfg in (LAB, AERIAL, BYOR, STATION)}
    assert {n: b.mobile for n, b in found["lab.xml"].items()} == {"turtlebot": True, "nao": False}
    assert found["lab.xml"]["turtlebot"].radius == pytest.approx(0.175)  # the Kobuki's URDF base
    assert {n: b.mobile for n, b in found["uavs.xml"].items()} == {"quadrotor": True, "hexarotor": True}
    assert found["uavs.xml"]["quadrotor"].why == "a multirotor"
    assert {n: b.mobile for n, b in found["scout.xml"].items()} == {"scout": True}
    assert found["scout.xml"]["scout"].why == "wheel joints left_wheel_joint, right_wheel_joint"  # scout.urdf's
    assert {n: b.mobile for n, b in found["sim_station.xml"].items()} == {"station_arm": False, "rover": True}


def test_the_aerial_copy_moves_both_starts_and_keeps_the_pads_and_the_rack(tmp_path: Path) -> None:
    original = ckmconf.load(AERIAL)
    assert original.environment is not None
    pads = {o.name: o for o in original.environment.objects}
    assert movable(original.environment) == []  # the pads are markings and landmarks
    for seed in (1, 2, 3):
        done = randomise(AERIAL, seed, tmp_path / f"seed{seed}")
        copy = ckmconf.load(done.config)
        assert verify_safely(copy) == []
        assert copy.environment is not None and copy.environment.objects == original.environment.objects
        assert copy.environment.avoided == original.environment.avoided  # the rack
        assert done.objects == {} and done.kept == {} and set(done.starts) == {"quadrotor", "hexarotor"}
        poses = _poses(copy)
        for body, pad in (("quadrotor", "pad_quad_home"), ("hexarotor", "pad_hexa_home")):
            nominal = [float(v) for v in _poses(original)[body].split()]
            x, y, yaw = done.starts[body]
            assert [float(v) for v in poses[body].split()] == pytest.approx([x, y, yaw], abs=1e-4)
            assert (x, y) != (nominal[0], nominal[1])
            assert abs(x - nominal[0]) <= 0.15 and abs(y - nominal[1]) <= 0.15 and abs(yaw - nominal[2]) <= 0.2
            assert footprint_distance(pads[pad], x, y) < 0  # still on its own pad
        # the noise: the fix, compass and range finder of each UAV, scaled by one factor; the truth is never noisy
        assert set(done.noise) == {f"{u}_fc/{u}_{s}" for u in ("quad", "hexa") for s in ("fix", "compass", "range")}
        assert done.noise["quad_fc/quad_fix"] == pytest.approx(0.03 * done.noise_factor)
        assert "objects moved: none; starts moved: quadrotor, hexarotor; noise ×" in done.describe()


def test_the_same_seed_gives_the_same_aerial_copy(tmp_path: Path) -> None:
    first, again, other = (randomise(AERIAL, s, tmp_path / d) for s, d in ((4, "a"), (4, "b"), (5, "c")))
    assert first.to_json() == again.to_json() != other.to_json()
    assert (tmp_path / "a" / "uavs.xml").read_bytes() == (tmp_path / "b" / "uavs.xml").read_bytes()
    assert (tmp_path / "a" / "uavs.xml").read_bytes() != (tmp_path / "c" / "uavs.xml").read_bytes()


def test_the_scout_moves_with_its_navigation_estimate_and_stays_clear(tmp_path: Path) -> None:
    original = ckmconf.load(BYOR)
    assert original.environment is not None
    (scout,) = bodies(original)
    assert scout.radius is not None
    clearance = scout.radius + START_MARGIN
    for seed in (1, 2, 3, 4):
        done = randomise(BYOR, seed, tmp_path / f"seed{seed}")
        copy = ckmconf.load(done.config)
        assert verify_safely(copy) == []
        assert copy.environment is not None and copy.environment.objects == original.environment.objects  # the pallet
        x, y, _ = start = done.starts["scout"]
        assert done.start_params == ["Navigation/nav/initialPose"]
        nav = next(p for p in _params(done.config.parent / "services.xml") if p["_name"] == "nav")
        assert [float(v) for v in nav["initialPose"].split()] == pytest.approx(start, abs=1e-4)
        assert [float(v) for v in _poses(copy)["scout"].split()] == pytest.approx(start, abs=1e-4)
        dock = next(a for a in copy.environment.areas if a.name == "DockArea")
        xs, ys = [p[0] for p in dock.points()], [p[1] for p in dock.points()]
        assert min(xs) + clearance <= x <= max(xs) - clearance and min(ys) + clearance <= y <= max(ys) - clearance
        assert all(footprint_distance(o, x, y) >= clearance for o in copy.environment.objects)
        # the wheel encoders give no noise: the device table's typical 20 ticks/s, like the lidar's own 1 cm, scaled
        channels = {p["_name"]: p for p in _params(done.config.parent / "robot.xml") if p["_tag"] == "HWChannel"}
        for name, base in (("left_encoder", 20.0), ("right_encoder", 20.0), ("lidar", 0.01)):
            assert float(channels[name]["noise"]) == pytest.approx(base * done.noise_factor)
        assert "noise" not in channels["true_pose"] and channels["left_encoder"]["seed"] == str(seed)
        plan = WorldPlan.of(list(copy.nodes))
        assert plan is not None and plan.seed == seed
        assert [float(v) for v in plan.bodies["scout"][1].split()] == pytest.approx(start, abs=1e-4)


def test_a_fixed_base_arm_stays_and_the_part_moves_on_its_table(tmp_path: Path) -> None:
    original = ckmconf.load(STATION)
    assert original.environment is not None
    table = next(o for o in original.environment.objects if o.name == "station_table")
    part = next(o for o in original.environment.objects if o.name == "part")
    assert movable(original.environment) == ["part"]  # the table is a landmark
    done = randomise(STATION, 6, tmp_path / "seed6")
    copy = ckmconf.load(done.config)
    assert verify_safely(copy) == []
    assert _poses(copy)["station_arm"] == _poses(original)["station_arm"]
    assert "fixed-base" in done.kept["station_arm"] and set(done.starts) == {"rover"}
    x, y, _ = done.objects["part"]
    assert footprint_distance(table, x, y) <= -radius(part)  # on the table, inside its edge
    assert math.hypot(x - part.pose.x, y - part.pose.y) <= 0.03 * math.sqrt(2) + 1e-9
    # the other examples copied beside it are not part of its system: never edited
    assert set(done.noise) == {"cell/left_encoder", "cell/laser"}
    beside = STATION.parent / "sim_multirotor.xml"
    assert (done.config.parent / beside.name).read_bytes() == beside.read_bytes()


def _with_randomise(config: Path, element: str, out: Path) -> Path:
    """A copy of ``config``'s directory whose System file's ``<Validation>`` holds ``element``."""
    out.mkdir()
    for path in config.parent.iterdir():
        if path.is_file():
            (out / path.name).write_bytes(path.read_bytes())
    text = (out / config.name).read_text()
    validation = re.search(r"<Validation[^>]*?/>", text)
    if validation is not None:
        text = text.replace(validation[0], validation[0][:-2] + ">" + element + "</Validation>")
    else:  # the Validation goes just before the Environment
        text = text.replace("<Environment ", f"<Validation>{element}</Validation>\n  <Environment ", 1)
    (out / config.name).write_text(text)
    return out / config.name


def test_randomise_can_hold_everything_and_the_line_says_so(tmp_path: Path) -> None:
    held = _with_randomise(AERIAL, '<Randomise objects="" startXY="0" startYaw="0"/>', tmp_path / "held")
    done = randomise(held, 3, tmp_path / "seed3")
    assert done.objects == {} and done.starts == {}
    copy = ckmconf.load(done.config)
    assert copy.environment == ckmconf.load(AERIAL).environment and _poses(copy) == _poses(ckmconf.load(AERIAL))
    line = done.describe()
    assert line.startswith("seed 3: objects moved: none; starts moved: none; starts kept: quadrotor (startXY and")
    assert "noise ×" in line


def test_randomise_names_the_objects_and_an_unknown_one_fails_at_its_line(tmp_path: Path) -> None:
    named = _with_randomise(STATION, '<Randomise objects="part" objectXY="0.01"/>', tmp_path / "named")
    done = randomise(named, 2, tmp_path / "seed2")
    part = next(o for o in ckmconf.load(STATION).environment.objects if o.name == "part")  # type: ignore[union-attr]
    assert abs(done.objects["part"][0] - part.pose.x) <= 0.01 and abs(done.objects["part"][1] - part.pose.y) <= 0.01
    wrong = _with_randomise(STATION, '<Randomise objects="prat"/>', tmp_path / "wrong")
    with pytest.raises(ckmconf.ConfigError) as raised:
        ckmconf.load(wrong)
    line = next(n for n, text in enumerate(wrong.read_text().splitlines(), 1) if "<Randomise" in text)
    assert re.search(
        rf"{re.escape(str(wrong))}:{line}:\d+: .*Randomise/@objects: object 'prat' does not exist in the environment; "
        r"did you mean 'part'\?",
        str(raised.value),
    )


def test_a_named_table_holding_an_object_is_refused(tmp_path: Path) -> None:
    named = _with_randomise(STATION, '<Randomise objects="station_table"/>', tmp_path / "table")
    with pytest.raises(ValueError, match="'station_table' holds part up"):
        randomise(named, 1, tmp_path / "seed1")


def test_markings_are_never_obstacles_nor_moved_by_the_rule() -> None:
    env = ckmconf.load(AERIAL).environment
    assert env is not None and all(is_marking(o) for o in env.objects)
    lab = ckmconf.load(LAB).environment
    assert lab is not None
    # without its <Randomise>, the lab would move every free object and the chair (restricted to its area)
    assert movable(lab) == [
        "chair", "cylinder_red_stripes", "cylinder_blue_dots", "cylinder_green_checker", "box_cereal", "box_orange",
    ]  # fmt: skip
