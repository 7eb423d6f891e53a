"""SRFlowGen (runtime.missions.validation.srflowgen): chains, k, P and eq. 5.7."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import System, Validation
from runtime.missions.validation import srflowgen
from runtime.missions.validation.srflowgen import service_probability

DATA = Path(__file__).parents[2] / "data" / "missions"
USECASE = Path(__file__).parents[3] / "configs" / "usecase" / "lab.xml"


def line_of(path: Path, needle: str) -> int:
    lines = [n for n, text in enumerate(path.read_text().splitlines(), start=1) if needle in text]
    assert len(lines) == 1, f"{needle!r} is on lines {lines} of {path.name}"
    return lines[0]


def test_clean_chain() -> None:
    findings, report = srflowgen(ckmconf.load(DATA / "clean.xml"), "Patrol", strict=True)
    assert findings == []
    go = report.state("Patrol", "GO")
    assert go is not None
    assert [v.name for v in go.variables] == ["nav.dispersion", "input pose (/pose)"]
    variable = go.variables[0]
    assert variable.chains == (("Nav.Loc", "robot/lidar (sensor)"),)
    assert variable.k == 1
    assert variable.probability == pytest.approx(0.99 * 0.98)
    assert dict(variable.factors) == {"Nav.Loc": pytest.approx(0.9702)}
    stop = report.state("Patrol", "STOP")
    assert stop is not None and stop.variables == () and stop.probability == 1.0 and stop.k == 0
    assert (report.p_min, report.k_max) == (0.9, 5)


def test_low_probability_chain_violates_eq_5_7() -> None:
    path = DATA / "low_probability.xml"
    findings, report = srflowgen(ckmconf.load(path), "Follow")
    (found,) = findings
    assert (found.kind, found.severity, found.state) == ("quality-flow", "error", "FOLLOW")
    assert (found.file, found.line) == (str(path), line_of(path, '<Require measure="deadline" upper="0.2"'))
    assert found.message == (
        "state 'FOLLOW' (behavior 'FOLLOW') of mission 'Follow': P(QR | R_1:k) = 0.8 for track.deadline, not >"
        " P_min = 0.9 (eq. 5.7); weakest service Vision.Track (0.8); raise the probability of the services'"
        " policies, depend on fewer services, or lower pMin"
    )
    state = report.state("Follow", "FOLLOW")
    assert state is not None
    (variable,) = state.variables
    assert variable.chains == (("Vision.Track", "Vision.Detect", "robot/camera (sensor)"),)
    assert variable.k == 2
    assert variable.probability == pytest.approx(0.8)  # the weakest step, not the product
    # With a lower P_min it passes, and with K_max = k the chain is too long (eq. 5.7: k < K_max).
    assert srflowgen(ckmconf.load(path), "Follow", Validation(p_min=0.7))[0] == []
    (long,) = srflowgen(ckmconf.load(path), "Follow", Validation(p_min=0.7, k_max=2))[0]
    assert (long.kind, long.line) == ("chain-too-long", found.line)


def test_topic_without_producer() -> None:
    path = DATA / "no_producer.xml"
    findings, report = srflowgen(ckmconf.load(path), "Patrol")
    (found,) = findings
    assert (found.kind, found.severity) == ("no-producer", "warning")
    assert (found.file, found.line) == (str(path), line_of(path, '<Input name="imu" topic="/imu"/>'))
    assert "topic '/imu', read by Fusion.Fuse on the flow of state 'GO'" in found.message
    state = report.state("Patrol", "GO")
    assert state is not None
    assert state.variables[0].chains == (
        ("Fusion.Fuse", "Nav.Loc", "robot/lidar (sensor)"),
        ("Fusion.Fuse", "? /imu"),
    )
    assert state.variables[0].uncharacterised == ("Fusion.Fuse",)


def test_strict_reports_uncharacterised_services() -> None:
    path = DATA / "no_producer.xml"
    findings, _ = srflowgen(ckmconf.load(path), "Patrol", strict=True)
    (warning,) = [f for f in findings if f.kind == "quality-not-characterised"]
    assert (warning.severity, warning.line) == ("warning", line_of(path, '<Service name="Fuse"'))


def test_unmeetable_requirement_has_no_probability() -> None:
    findings, report = srflowgen(ckmconf.load(DATA / "unmeetable_requirement.xml"), "Patrol")
    assert [f.kind for f in findings] == ["quality-flow"]
    state = report.state("Patrol", "GO")
    assert state is not None and state.probability == 0.0


def test_service_probability() -> None:
    system = ckmconf.load(USECASE)
    found = system.service("RGBDCamera.RGBRecog")
    assert found is not None
    assert service_probability(found[1]) == pytest.approx(0.95)  # best scenario; its CPU policy is spatial
    amcl = system.service("Navigation.AMCL")
    assert amcl is not None and service_probability(amcl[1]) == pytest.approx(0.95)  # its dispersion policy


def test_unknown_mission() -> None:
    findings, report = srflowgen(ckmconf.load(DATA / "clean.xml"), "Nope")
    assert [f.kind for f in findings] == ["unknown-mission"]
    assert report.states == ()


# ----------------------------------------------------------------------------- the use case


@pytest.fixture(scope="module")
def usecase() -> System:
    return ckmconf.load(USECASE)


QUALITY = 0.9  # the weakest step: Fusion's, Pan-Tilt Recog.'s and Track's policies; APPR reads the fusion (D207, D253)
MOBILE = 0.95  # AMCL's, Scan's and Displacement's policies
ARM = 0.99  # MoveIt's "active" policy
PLACE = {("ObjectPlace", "NAV"): MOBILE, ("ObjectPlace", "WAIT"): MOBILE, ("ObjectPlace", "DOCK"): MOBILE,
         ("ObjectPlace", "PLACE"): ARM,
         ("ObjectPlace", "BACK"): MOBILE,
         # the dropped-object recovery (issue K.3d): the drive home again, and ObjectRecovery
         ("ObjectPlace", "RENAV"): MOBILE, ("ObjectPlace", "REWAIT"): MOBILE,
         ("ObjectRecovery", "HALT"): MOBILE, ("ObjectRecovery", "STOW"): ARM, ("ObjectRecovery", "LOOK"): QUALITY,
         ("ObjectRecovery", "APPR"): QUALITY, ("ObjectRecovery", "PICK"): ARM, ("ObjectRecovery", "RELEASE"): ARM,
         ("ObjectRecovery", "BACK"): MOBILE, ("ObjectRecovery", "RESTOW"): ARM}  # fmt: skip


@pytest.mark.parametrize(
    ("mission", "flows", "weakest"),
    [
        ("Agent1Fetch",
         {("Navigation", "NAV"): MOBILE, ("Navigation", "WAIT"): MOBILE, ("ObjectInteraction", "SPOT"): QUALITY,
          ("ObjectInteraction", "APPR"): QUALITY, ("ObjectInteraction", "PICK"): ARM,
          ("ObjectInteraction", "RELEASE"): ARM, ("ObjectInteraction", "BACK"): MOBILE,
          ("ObjectInteraction", "STOW"): ARM, **PLACE},
         {("ObjectInteraction", "SPOT"), ("ObjectInteraction", "APPR"), ("ObjectRecovery", "LOOK"),
          ("ObjectRecovery", "APPR")}),
        ("Agent1FetchCoop",
         {("NavigationCoop", "NAV"): QUALITY, ("NavigationCoop", "WAIT"): MOBILE,
          ("ObjectInteractionCoop", "SPOT"): QUALITY, ("ObjectInteractionCoop", "APPR"): QUALITY,
          ("ObjectInteractionCoop", "PICK"): ARM, ("ObjectInteractionCoop", "RELEASE"): ARM,
          ("ObjectInteractionCoop", "BACK"): MOBILE, ("ObjectInteractionCoop", "STOW"): ARM, **PLACE},
         {("NavigationCoop", "NAV"), ("ObjectInteractionCoop", "SPOT"), ("ObjectInteractionCoop", "APPR"),
          ("ObjectRecovery", "LOOK"), ("ObjectRecovery", "APPR")}),
        ("Agent2Spot", {("Agent2Spot", "OBJ_TRACK"): QUALITY, ("Agent2Spot", "OBJ_FIX"): QUALITY},
         {("Agent2Spot", "OBJ_TRACK"), ("Agent2Spot", "OBJ_FIX")}),
    ],
)  # fmt: skip
def test_usecase_flow(
    usecase: System, mission: str, flows: dict[tuple[str, str], float], weakest: set[tuple[str, str]]
) -> None:
    """The lab as configured passes eq. 5.7 (P_min = 0.85): each state has the probability of the
    weakest policy among the services it reads (recognisers and tracking 0.9, the mobile base's
    services 0.95, the arm 0.99); states with no service have 1."""
    findings, report = srflowgen(usecase, mission)
    assert findings == []
    for state in report.states:
        expected = flows.get((state.mission, state.state), 1.0)
        assert state.probability == pytest.approx(expected), (state.mission, state.state)
        assert state.k < report.k_max
    json.dumps(report.to_json())
    # At P_min = 0.9 the weakest states fail: eq. 5.7 is a strict inequality.
    strict = srflowgen(usecase, mission, Validation(p_min=0.9, k_max=20))[0]
    assert {(f.kind, f.mission, f.state) for f in strict} == {("quality-flow", m, s) for m, s in weakest}


def test_usecase_passes_apart_from_p_min(usecase: System) -> None:
    """Nothing else is wrong: with P_min under the weakest flow, no finding at all."""
    relaxed = Validation(p_min=0.5, k_max=20)
    for mission in ("Agent1Fetch", "Agent1FetchCoop", "Agent2Spot"):
        assert srflowgen(usecase, mission, relaxed)[0] == [], mission


def test_usecase_chains(usecase: System) -> None:
    _, report = srflowgen(usecase, "Agent1Fetch")
    wait = report.state("Navigation", "WAIT")
    assert wait is not None
    pose = next(v for v in wait.variables if v.name == "input pose (/nav/pose)")
    # AMCL and Displacement feed each other (path / odom): the loop counts once, plus odometry.
    assert pose.k == 3
    assert ("Navigation.AMCL", "MobileBase.Displacement", "Navigation.AMCL (loop)") in pose.chains
    assert ("Navigation.AMCL", "LaserSensor.Scan", "turtlebot/lidar (sensor)") in pose.chains
    assert set(pose.uncharacterised) == set()  # every service on the chains has a policy now
    assert math.isclose(pose.probability, 0.95)
    spot = report.state("ObjectInteraction", "SPOT")
    assert spot is not None
    fusion = next(v for v in spot.variables if v.name == "fusion.reliability")
    assert ("GlobalRecog.Fusion", "RGBDCamera.RGBRecog", "turtlebot/rgb_camera (sensor)") in fusion.chains
    assert math.isclose(fusion.probability, QUALITY)
