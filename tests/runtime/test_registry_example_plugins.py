"""The example plugin package (examples/ckm-example-plugins, docs/writing-plugins.md), installed as
a separate distribution: its four kinds register through the ``ckm.plugins`` entry points, are
listed and verified like the built-in ones, work, and run under ckm-run."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ckmconf
from ckmconf.model import Controller as ControllerRecord
from ckmconf.model import HWChannel, Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorInput
from ckmconf.model.resources import Plugin, Profile, SmartResource, Use
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from runtime.registry import Registry
from runtime.resources.spt import Topology
from runtime.verification.verify import verify
from tests.conftest import REPO

PACKAGE = "ckm-example-plugins"
EXAMPLE = REPO / "examples" / PACKAGE / "example.xml"
KINDS = [("behavior", "wait-above"), ("controller", "hysteresis"), ("hardware", "sine"), ("plugin", "threshold")]


@pytest.fixture(scope="module")
def registry() -> Registry:
    registry = Registry()
    if not all(registry.origin(c, k) == PACKAGE for c, k in KINDS):
        pytest.fail(f"{PACKAGE} is not installed: run scripts/setup.sh (it installs examples/{PACKAGE})")
    return registry


def test_the_package_registers_its_kinds_through_entry_points(registry: Registry) -> None:
    only = Registry(packages=(PACKAGE,))
    assert only.names() == KINDS
    for category, kind in KINDS:
        assert registry.find(category, kind) is only.find(category, kind)


def test_the_example_system_verifies_with_the_package_and_not_without(registry: Registry) -> None:
    system = ckmconf.load(EXAMPLE)
    assert verify(system, registry) == []
    ckm = Registry(packages=("ckm",))
    missing = [e.message for e in verify(system, ckm)]
    assert missing == [
        f"hardware backend 'sine' does not exist in the registry (defined: {', '.join(ckm.kinds('hardware'))})",
        f"controller kind 'hysteresis' does not exist in the registry (defined: {', '.join(ckm.kinds('controller'))})",
    ]


def test_bad_params_of_an_example_kind_are_located(registry: Registry, tmp_path: Path) -> None:
    text = EXAMPLE.read_text().replace('name="frequency" value="0.5"', 'name="frequency" value="0"')
    path = tmp_path / "bad.xml"
    path.write_text(text)
    [problem] = verify(ckmconf.load(path), registry)
    assert problem.line == 10 and problem.xpath.endswith("/Param[@name='frequency']/@value")
    assert problem.message == "hardware backend 'sine': parameter 'frequency' = 0.0 must be greater than 0"


def test_sine_backend_reads_its_wave(registry: Registry) -> None:
    params = (Param(name="amplitude", value="2"), Param(name="offset", value="20"))
    backend = registry.resolve("hardware", "sine")(HWChannel(name="t", direction="in", params=params))
    backend.setup()
    assert all(18.0 <= backend.read() <= 22.0 for _ in range(20))


def test_hysteresis_switches_outside_its_band_only(registry: Registry) -> None:
    record = ControllerRecord(name="c", kind="hysteresis", period=0.1, params=(Param(name="band", value="1"),))
    controller = registry.resolve("controller", "hysteresis")(record)
    outputs = [controller.step({"measure": m, "setpoint": 20.0}, 0.1) for m in (18.0, 19.8, 20.4, 20.6, 20.2, 19.4)]
    assert outputs == [1.0, 1.0, 1.0, 0.0, 0.0, 1.0]
    bad = ControllerRecord(name="c", kind="hysteresis", period=0.1, params=(Param(name="low", value="2"),))
    with pytest.raises(ParamError, match=r"'low' = 2\.0 must be below 'high' = 1\.0"):
        registry.resolve("controller", "hysteresis")(bad)


def test_threshold_runs_in_a_topology(registry: Registry) -> None:
    resource = SmartResource(
        name="cam",
        node="n",
        plugins=(Plugin(name="mask", kind="threshold", params=(Param(name="level", value="100"),)),),
        profiles=(Profile(name="p", root=Use(plugin="mask")),),
    )
    topology = Topology(resource, registry)
    topology.select("s", "p")
    image = np.array([[0, 99, 100, 255]], dtype=np.uint8)
    frame = topology.run(image)
    assert frame.outputs["s"].tolist() == [[0, 0, 255, 255]]
    assert image.tolist() == [[0, 99, 100, 255]]  # the input is left alone


def test_wait_above_follows_its_input(registry: Registry) -> None:
    value: list[float | None] = [None]
    record = BehaviorRecord(
        name="WARM",
        kind="wait-above",
        params=(Param(name="threshold", value="21"), Param(name="start", value="19")),
        inputs=(BehaviorInput(name="temperature", topic="temperature"),),
    )
    context = BehaviorContext(services={}, inputs={"temperature": lambda: value[0]}, outputs={}, now=lambda: 0.0)
    behavior = registry.resolve("behavior", "wait-above")(record, context)
    assert behavior.step().progress == 0.0
    value[0] = 20.0
    assert (behavior.step().progress, behavior.step().done) == (0.5, False)
    value[0] = 21.5
    assert behavior.step().done


def test_ckm_run_runs_the_example(registry: Registry, tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "runtime.cli", str(EXAMPLE), "--duration", "1", "--log-dir", str(tmp_path / "run")],
        cwd=REPO,
        timeout=120,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    tasks = json.loads((tmp_path / "run" / "stats.json").read_text())["nodes"]["room"]["tasks"]
    assert tasks["room.thermostat"]["releases"] > 0 and tasks["room.thermostat"]["failures"] == 0
