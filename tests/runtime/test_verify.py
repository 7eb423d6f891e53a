"""Verify before build (issue G): the corpus of configurations that load but cannot run, and verify itself.

Every file of ``tests/data/verify/`` passes the schema check and is refused by ``ckm-validate``
with exactly the lines of ``expected.json``, verified against the kinds the ``ckm`` distribution
registers. Also: the example configurations, ``--schema-only``, ``verify_or_report`` for
``ckm-run``, and that nothing is instantiated.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any, ClassVar

import pytest

import ckmconf
from ckmconf import cli
from ckmconf.model import Controller as ControllerRecord
from ckmconf.model import HWChannel, System, params_dict
from runtime.kernel.interfaces import Backend, Controller, Value
from runtime.registry import Registry
from runtime.validate_cli import main as validate_main
from runtime.verification.manifest import NUMBER, REQUIRED, P, Params, Ports
from runtime.verification.verify import verify, verify_or_report, verify_safely
from tests.conftest import REPO

CORPUS = REPO / "tests" / "data" / "verify"
EXPECTED = CORPUS / "expected.json"
FILES = sorted(CORPUS.glob("*.xml"))
EXAMPLES_DIR = REPO / "configs" / "examples"
EXAMPLES = sorted([*EXAMPLES_DIR.glob("*.xml"), *EXAMPLES_DIR.glob("split/*.xml")])

# Examples that describe what no code runs yet: verify must say so, located, with the words
# "not runnable" (configs/examples/README.md says why). Fixing one means moving it out of this set.
NOT_RUNNABLE = {
    "ros_resource.xml",  # a ROS-kernel resource (issue L)
}


@cache
def builtin() -> Registry:
    """The kinds of this distribution only, so the expected lines do not depend on what else is installed."""
    return Registry(packages=("ckm",))


def relative(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


def validate(*files: str, json_out: bool = False, registry: Registry | None = None) -> int:
    """ckm-validate in process, verifying against ``registry`` (default: the built-in kinds)."""
    args = argparse.Namespace(files=list(files), json=json_out, summary=False, max_bytes=ckmconf.Limits().max_bytes)
    return cli.run(args, lambda system: verify_safely(system, registry or builtin()))


def generate() -> dict[str, list[str]]:
    """What expected.json should hold (run from the repository root)."""
    import contextlib
    import io

    found: dict[str, list[str]] = {}
    for path in FILES:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            validate(relative(path))
        found[path.name] = out.getvalue().splitlines()
    return found


@cache
def expected() -> dict[str, list[str]]:
    data = json.loads(EXPECTED.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


@pytest.fixture
def at_repo(monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(REPO)
    return REPO


# ---------------------------------------------------------------- the corpus


def test_corpus_and_expected_match() -> None:
    assert len(FILES) >= 15
    assert sorted(expected()) == [path.name for path in FILES]
    assert all(expected()[path.name] for path in FILES), "every file must be refused"


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_schema_check_accepts_the_file(path: Path, at_repo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["--schema-only", relative(path)]) == 0
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_verify_reports_exactly_the_expected_lines(
    path: Path, at_repo: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert validate(relative(path)) == 1
    captured = capsys.readouterr()
    assert captured.err == ""
    assert captured.out.splitlines() == expected()[path.name]


def test_json_lists_the_same_problems(at_repo: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert validate(*map(relative, FILES), json_out=True) == 1
    problems = json.loads(capsys.readouterr().out)
    lines = [f"{p['file']}:{p['line']}:{p['column']}: {p['xpath']}: {p['message']}" for p in problems]
    assert lines == [line for path in FILES for line in expected()[path.name]]


def test_the_installed_command_verifies_by_default() -> None:
    """The console script, in a fresh process: exit 1 with the located line, never a traceback."""
    target = relative(CORPUS / "param_wrong_type.xml")
    done = subprocess.run(
        [sys.executable, "-m", "runtime.validate_cli", target], cwd=REPO, timeout=120, capture_output=True, text=True
    )
    assert (done.returncode, done.stderr) == (1, "")
    assert done.stdout.splitlines() == expected()["param_wrong_type.xml"]
    assert done.stdout.startswith(f"{target}:11:24: ")
    bare = subprocess.run(
        [sys.executable, "-m", "runtime.validate_cli", "--schema-only", target],
        cwd=REPO,
        timeout=120,
        capture_output=True,
        text=True,
    )
    assert (bare.returncode, bare.stdout, bare.stderr) == (0, "", "")


def test_load_problems_come_first_and_verify_does_not_run_on_a_broken_file(
    at_repo: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert validate("configs/invalid/sensor_unknown_channel.xml") == 1
    [line] = capsys.readouterr().out.splitlines()
    assert "HWChannel 'encodr' does not exist" in line


# ---------------------------------------------------------------- the example configurations


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.relative_to(EXAMPLES_DIR).as_posix())
def test_examples_verify_or_are_known_not_runnable(path: Path) -> None:
    """Every example and every Part of the split system verifies, or is reported not runnable."""
    system = ckmconf.load(path)
    problems = verify(system, builtin())
    name = path.relative_to(EXAMPLES_DIR).as_posix()
    if name in NOT_RUNNABLE:
        assert problems, f"{name} verifies now: remove it from NOT_RUNNABLE"
        assert all("(not runnable)" in p.message for p in problems), [str(p) for p in problems]
    else:
        assert [str(p) for p in problems] == []


def test_the_ros_resource_example_is_not_runnable_only_for_its_ros_kernel() -> None:
    """Point 8: the ROS-kernel resource is reported at its line; the CKM resource beside it verifies."""
    path = EXAMPLES_DIR / "ros_resource.xml"
    lines = path.read_text().splitlines()
    line = next(i for i, text in enumerate(lines, 1) if '<SmartResource name="RoboticArm"' in text)
    [problem] = verify(ckmconf.load(path), builtin())
    assert (problem.file, problem.line) == (str(path), line)
    assert problem.xpath.endswith("SmartResource[@name='RoboticArm']/@kernel")
    assert "runs on a ROS kernel" in problem.message and "(not runnable)" in problem.message


def test_the_examples_readme_has_a_line_for_every_example() -> None:
    """configs/examples/README.md: each example's concept and its command, or why it is a model only."""
    rows = {
        line.split("|")[1].strip().split()[0].strip("`"): line
        for line in (EXAMPLES_DIR / "README.md").read_text().splitlines()
        if line.startswith("| `")
    }
    assert set(rows) == {p.name for p in EXAMPLES_DIR.glob("*.xml")}
    for name, row in rows.items():
        command = row.rsplit("|", 2)[-2]
        if name in NOT_RUNNABLE:
            assert "model only:" in command, name
        else:
            assert f"configs/examples/{name}" in command or "model only:" in command, name


# Examples whose plan reaches its mission's success final on what this repository runs today.
PLAN_RUNS = [
    ("mission_nested.xml", "fetch", "robot", "delivered"),
    ("split_system.xml", "delivery", "robot", "delivered"),
    ("plan_signal_payload.xml", "report-and-fetch", "fetcher", "fetched"),
]


@pytest.mark.parametrize(("name", "plan", "agent", "outcome"), PLAN_RUNS, ids=[r[0] for r in PLAN_RUNS])
def test_plan_examples_run_to_their_success_final(
    name: str, plan: str, agent: str, outcome: str, tmp_path: Path
) -> None:
    """ckm-run FILE --plan PLAN exits 0 (verified, built, every agent succeeded) before its duration ends."""
    command = [sys.executable, "-m", "runtime.cli", str(EXAMPLES_DIR / name), "--plan", plan]
    done = subprocess.run(
        [*command, "--duration", "30", "--log-dir", str(tmp_path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert done.returncode == 0, done.stderr
    records = [json.loads(line) for line in (tmp_path / f"mission-{agent}.jsonl").read_text().splitlines()]
    assert [r["outcome"] for r in records if r["kind"] == "end"] == [outcome]


def test_the_behavior_services_example_recognizes_what_its_spot_behavior_looks_for() -> None:
    """behavior_services.xml's RGB service, on its real plugins and synthetic frames (no camera runs
    under ckm-run yet, issue J), publishes objects in which SPOT's spot-objects finds its target."""
    from ckm_lab.scenes import render_rgb_scene

    from plugins.behaviors.messages import find_target
    from runtime.network import TopicQoS, open_transport
    from runtime.resources import codec
    from runtime.resources.resource import SmartResourceRuntime
    from tests.runtime.network.conftest import private_network
    from tests.runtime.resources.test_service_api import until

    system = ckmconf.load(EXAMPLES_DIR / "behavior_services.xml")
    resource, spot = system.resource("RGBD"), system.behavior("SPOT")
    assert resource is not None and spot is not None
    target, texture = (params_dict(spot.params)[k] for k in ("target", "targetTexture"))
    frames = [render_rgb_scene(["cylinder_red_stripes", "box_cereal"], seed=i).image for i in range(3)]
    counter = iter(range(10**9))
    network = private_network()
    server, client = open_transport(network, name="resource"), open_transport(network, name="client")
    results: list[Any] = []
    try:
        for transport in (server, client):
            transport.setup()
            transport.start()
        client.subscribe(
            TopicQoS("/rgbd/rgb-objects", "ckm/service-data"), lambda s: results.append(codec.decode(s.value))
        )
        with SmartResourceRuntime(resource, server, sources={"grab": lambda: frames[next(counter) % 3]}):
            assert until(lambda: any(find_target(r, target, texture) for r in results), timeout=30)
    finally:
        for transport in (server, client):
            transport.stop()


def test_the_use_case_verifies_every_kind_runs() -> None:
    """Issue J point 6: every kind the use case names exists, its Params and ports check, and no
    resource is left on a kernel the runtime does not provide: verify finds nothing."""
    messages = [e.message for e in verify(ckmconf.load(REPO / "configs" / "usecase" / "lab.xml"), builtin())]
    assert messages == []


# ---------------------------------------------------------------- verify itself


class Probe(Controller):
    """A controller that counts its instances: verify must never build one."""

    built: ClassVar[int] = 0
    PARAMS = Params(P("mode", REQUIRED, "Required.", type=str, choices=("a", "b")), P("gain", 1.0, "", min=0.0))
    PORTS = Ports(inputs={"measure": NUMBER, "*": "string"})

    def __init__(self, record: ControllerRecord) -> None:
        Probe.built += 1
        super().__init__(record)

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        return 0.0


SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="probe">
  <Node name="n">
    <Topic name="x" type="float64" scope="internal"/>
    <Topic name="label" type="string" scope="internal"/>
    <Controller name="c" kind="probe" period="0.1">{params}
      <Input topic="x" role="measure"/>
      <Input topic="x" role="other"/>
      <Input topic="label" role="name"/>
      <Output topic="x"/>
    </Controller>
  </Node>
</System>
"""


def probe_system(tmp_path: Path, params: str) -> System:
    path = tmp_path / "probe.xml"
    path.write_text(SYSTEM.format(params=params))
    return ckmconf.load(path)


def probe_registry() -> Registry:
    registry = Registry(load_entry_points=False)
    registry.register("controller", "probe", Probe)
    return registry


def test_verify_checks_declared_ports_and_params_without_building(tmp_path: Path) -> None:
    system = probe_system(tmp_path, '\n      <Param name="mode" value="c"/>\n      <Param name="gain" value="-1"/>')
    problems = [(e.line, e.xpath.rsplit("/", 1)[-1], e.message) for e in verify(system, probe_registry())]
    assert Probe.built == 0
    assert problems == [
        (7, "@value", "controller kind 'probe': parameter 'mode' = 'c' must be one of a, b"),
        (8, "@value", "controller kind 'probe': parameter 'gain' = -1.0 must not be negative"),
        (10, "@topic", "controller 'c' (probe) reads string values as 'other', but topic 'x' is of type float64"),
    ]


def test_missing_required_param_is_reported_at_the_element(tmp_path: Path) -> None:
    [problem] = [e for e in verify(probe_system(tmp_path, ""), probe_registry()) if "needs" in e.message]
    assert problem.line == 6 and problem.xpath.endswith("/Controller[@name='c']")
    assert problem.message == "controller kind 'probe' needs parameter 'mode' (Required.)"


def test_a_broken_manifest_is_one_located_problem_not_a_traceback(tmp_path: Path) -> None:
    class Broken(Probe):
        PARAMS: ClassVar[Any] = 5  # not a mapping

    registry = Registry(load_entry_points=False)
    registry.register("controller", "probe", Broken)
    [problem] = verify_safely(probe_system(tmp_path, ""), registry)
    assert problem.message.startswith("verification failed: ")
    assert problem.file.endswith("probe.xml")


def test_verify_or_report_for_ckm_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = ckmconf.load(REPO / "configs" / "examples" / "closed_loop.xml")
    assert verify_or_report(good, "closed_loop.xml", builtin()) is None
    assert capsys.readouterr().err == ""
    bad = probe_system(tmp_path, "")
    assert verify_or_report(bad, "probe.xml", probe_registry()) == 1
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].endswith("controller kind 'probe' needs parameter 'mode' (Required.)")
    assert "reads string values as 'other'" in lines[1]
    assert lines[-1] == "probe.xml: 2 problem(s) found before start; nothing was started"


class Camera(Backend):
    """A backend whose reads depend on a Param: images for sensor=rgb, numbers otherwise."""

    PARAMS = Params(P("sensor", "joint", "What the channel reads."))

    @classmethod
    def value_type(cls, channel: HWChannel) -> str:
        return "Image" if params_dict(channel.params).get("sensor") == "rgb" else NUMBER

    def read(self) -> float:
        return 0.0

    def write(self, value: Value) -> None:
        return None


CAMERA = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="camera">
  <MessageType name="Image"><Field name="data" type="bytes"/></MessageType>
  <Node name="n">
    <HWChannel name="rgb" direction="in" kind="stream" backend="camera"><Param name="sensor" value="rgb"/></HWChannel>
    <HWChannel name="pan" direction="in" kind="analog" backend="camera"/>
    <Topic name="image" type="Image" scope="internal"/>
    <Topic name="angle" type="float64" scope="internal"/>
    <Topic name="other" type="float64" scope="internal"/>
    <Sensor name="rgb" channel="rgb" topic="image" period="0.1"/>
    <Sensor name="pan" channel="pan" topic="angle" period="0.1"/>
    <Sensor name="wrong" channel="rgb" topic="other" period="0.1"/>
  </Node>
</System>
"""


def test_a_backend_may_type_its_reads_from_its_params(tmp_path: Path) -> None:
    path = tmp_path / "camera.xml"
    path.write_text(CAMERA)
    registry = Registry(load_entry_points=False)
    registry.register("hardware", "camera", Camera)
    [problem] = verify(ckmconf.load(path), registry)
    assert problem.line == 12
    assert problem.message == (
        "sensor 'wrong' writes Image messages (channel 'rgb', size 1) onto topic 'other' of type float64"
    )


def test_the_console_scripts_point_at_the_verifying_commands() -> None:
    from importlib.metadata import entry_points

    scripts = {point.name: point.value for point in entry_points(group="console_scripts")}
    assert scripts["ckm-validate"] == "runtime.validate_cli:main"
    assert scripts["ckm-plugins"] == "runtime.plugins_cli:main"


def test_a_part_included_by_several_files_is_reported_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "part.xml").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n<Part xmlns="urn:ckm:1" version="1.0">\n'
        '  <Behavior name="GOTO" kind="follow-path" timeout="10"/>\n</Part>\n'
    )
    for name in ("a", "b"):
        (tmp_path / f"{name}.xml").write_text(
            '<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<System xmlns="urn:ckm:1" version="1.0" name="{name}">\n  <Include href="part.xml"/>\n</System>\n'
        )
    assert validate(str(tmp_path / "a.xml"), str(tmp_path / "b.xml")) == 1
    [line] = capsys.readouterr().out.splitlines()
    assert line.startswith(f"{tmp_path / 'part.xml'}:3:25: ") and "'follow-path' does not exist" in line


if __name__ == "__main__":  # regenerate expected.json (see tests/data/verify/README.md)
    import os

    os.chdir(REPO)
    EXPECTED.write_text(json.dumps(generate(), indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


# ---------------------------------------------------------------- service topics against processing plugins

DETECTIONS = (
    '<MessageType name="Detection"><Field name="name" type="string"/><Field name="matches" type="uint32"/>'
    '<Field name="inliers" type="uint32"/><Field name="x" type="float64"/><Field name="y" type="float64"/>'
    '<Field name="reliability" type="float64"/></MessageType><MessageType name="Detections">'
    '<Field name="objects" type="Detection" count="0"/><Field name="reliability" type="float64"/>'
    '<Field name="keypoints" type="uint32"/><Field name="width" type="uint32"/><Field name="height" type="uint32"/>'
    "</MessageType>"
)
"""Every field orb-recognition writes (docs/interfaces.md), so the type loses none of them (D277)."""

SERVICE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="ports">
  {detections}
  {topics}
  <Node name="pc"/>
  <SmartResource name="R" node="pc">
    <Plugin name="first" kind="{first}"/>
    <Plugin name="last" kind="{last}"/>
    <Profile name="p"><Use plugin="first"><Use plugin="last"/></Use></Profile>
    <Service name="S">
      {ports}
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="p" profile="p"><Policy measure="latency" upper="0.1"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


def service_problems(tmp_path: Path, first: str, last: str, topics: dict[str, str], ports: str) -> list[str]:
    """verify's messages for one service whose profile is first → last (the output plugin)."""
    path = tmp_path / "service.xml"
    declared = "\n  ".join(f'<Topic name="{name}" type="{kind}"/>' for name, kind in topics.items())
    path.write_text(SERVICE.format(detections=DETECTIONS, topics=declared, first=first, last=last, ports=ports))
    return [f"{e.line}: {e.message}" for e in verify(ckmconf.load(path), builtin())]


def test_a_service_output_that_fits_its_plugin_or_is_bytes_is_accepted(tmp_path: Path) -> None:
    topics = {"/raw": "bytes", "/objects": "Detections", "/blob": "bytes"}
    ports = '<Input name="image" topic="/raw"/><Output name="objects" topic="/objects"/>'
    assert service_problems(tmp_path, "camera-acquisition", "orb-recognition", topics, ports) == []
    ports = '<Input name="image" topic="/raw"/><Output name="image" topic="/blob"/>'
    assert service_problems(tmp_path, "camera-acquisition", "resize", topics, ports) == []


def test_an_image_output_on_a_structured_topic_is_reported(tmp_path: Path) -> None:
    topics = {"/raw": "bytes", "/objects": "Detections"}
    ports = '<Input name="image" topic="/raw"/><Output name="image" topic="/objects"/>'
    assert service_problems(tmp_path, "camera-acquisition", "grayscale", topics, ports) == [
        "12: service 'R.S' publishes arrays onto topic '/objects' of type Detections "
        "(the result of plugin 'last': grayscale)"
    ]


def test_an_acquisition_input_on_a_number_topic_is_reported(tmp_path: Path) -> None:
    topics = {"/raw": "float64", "/out": "bytes"}
    ports = '<Input name="image" topic="/raw"/><Output name="objects" topic="/out"/>'
    assert service_problems(tmp_path, "camera-acquisition", "orb-recognition", topics, ports) == [
        "12: acquisition plugin 'first' (camera-acquisition) of resource 'R' reads dicts of fields "
        "from Input 'image', but topic '/raw' is of type float64"
    ]


def test_several_outputs_take_fields_of_a_dict_result(tmp_path: Path) -> None:
    topics = {"/raw": "bytes", "/a": "bytes", "/b": "bytes"}
    ports = '<Input name="image" topic="/raw"/><Output name="a" topic="/a"/><Output name="b" topic="/b"/>'
    [problem] = service_problems(tmp_path, "camera-acquisition", "resize", topics, ports)
    assert problem.startswith("12: service 'R.S': plugin 'last' (resize, profile 'p') returns arrays")
    assert problem.endswith("nothing would be published (not runnable)")
    assert service_problems(tmp_path, "camera-acquisition", "orb-recognition", topics, ports) == []


def test_several_inputs_are_checked_by_name_against_the_acquisition_plugin(tmp_path: Path) -> None:
    topics = {"/odom": "float64", "/ranges": "string", "/pose": "bytes"}
    ports = (
        '<Input name="odometry" topic="/odom"/><Input name="ranges" topic="/ranges"/>'
        '<Output name="pose" topic="/pose"/>'
    )
    problems = service_problems(tmp_path, "localization", "localization", topics, ports)
    # the template's plugins have no Params: no map file, no laser mount
    unset = ("needs parameter 'environment'", "needs parameter 'laserPose'", "needs parameter 'laserHeight'")
    problems = [p for p in problems if not any(u in p for u in unset)]
    assert problems == [
        "13: acquisition plugin 'first' (localization) of resource 'R' reads vectors of numbers "
        "from Input 'ranges', but topic '/ranges' is of type string"
    ]
