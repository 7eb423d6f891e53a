"""``plugin.localization`` through the SPT plugin interface (issue I point 4): pose, covariance, dispersion."""

from __future__ import annotations

import tomllib
from collections.abc import Iterator
from pathlib import Path

import msgpack
import numpy as np
import pytest

from benchmarks.localization_worlds import Run, standard_runs
from ckmconf.errors import ConfigError
from ckmconf.model import Param
from ckmconf.model.resources import Plugin, Profile, SmartResource, Use
from plugins.localization.service import Localization
from runtime.registry import default_registry
from runtime.resources.spt import Context, Topology

ROOT = Path(__file__).resolve().parents[3]


def _resource(filter_name: str, **params: str) -> SmartResource:
    given = {
        "filter": filter_name,
        "particles": "2500",
        "seed": "7",
        "environment": str(ROOT / "configs" / "usecase" / "environment.xml"),
        # the benchmark's scans: 60 beams over a full turn, 8 m, from the robot's centre
        "laserPose": "0 0 0",
        "laserHeight": "0.2",
        "fov": str(2 * np.pi),
        "max_range": "8",
        **params,
    }
    plugin = Plugin(name="amcl", kind="localization", params=tuple(Param(name=k, value=v) for k, v in given.items()))
    profile = Profile(name="localize", output="amcl", root=Use(plugin="amcl"))
    return SmartResource(name="Navigation", node="remote_pc", plugins=(plugin,), profiles=(profile,))


@pytest.fixture(scope="module")
def lab_run() -> Run:
    return standard_runs(seed=1)[0]


def test_the_kind_is_registered_as_an_entry_point() -> None:
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["ckm.plugins"]
    assert declared["plugin.localization"] == "plugins.localization.service:Localization"
    assert default_registry().find("plugin", "localization") is Localization


@pytest.fixture(params=["reliability", "mcl"])
def topology(request: pytest.FixtureRequest) -> Iterator[Topology]:
    spt = Topology(_resource(request.param))
    spt.setup()
    spt.select("AMCL", "localize")
    yield spt
    spt.stop()


def test_plugin_publishes_pose_covariance_and_dispersion(topology: Topology, lab_run: Run) -> None:
    dispersions = []
    for k in range(len(lab_run.truth)):
        frame = topology.run({"odometry": lab_run.odometry[k].tolist(), "ranges": lab_run.scans[k].tolist()})
        message = frame.outputs["AMCL"]
        dispersions.append(message["dispersion"])
    assert set(message) == {"x", "y", "yaw", "covariance", "dispersion", "filter", "reliability"}
    assert np.hypot(message["x"] - lab_run.truth[-1, 0], message["y"] - lab_run.truth[-1, 1]) < 0.3
    covariance = np.array(message["covariance"]).reshape(3, 3)
    assert covariance == pytest.approx(covariance.T)
    assert np.all(np.linalg.eigvalsh(covariance) >= -1e-12)
    assert dispersions[0] > 2.0  # a uniform prior over the lab
    assert dispersions[-1] < dispersions[0] / 4  # the particles gathered
    assert msgpack.unpackb(msgpack.packb(message)) == message
    if message["filter"] == "reliability":
        assert 0.0 < message["reliability"] <= 1.0
    else:
        assert message["reliability"] is None


def test_bad_params_are_configuration_errors() -> None:
    with pytest.raises(ConfigError, match="filter"):
        Topology(_resource("ukf"))
    with pytest.raises(ConfigError, match="initial_pose"):
        Topology(_resource("mcl", initial_pose="1 2"))


def test_initial_pose_starts_tracking_there(lab_run: Run) -> None:
    x, y, yaw = lab_run.truth[0]
    plugin = Localization(_resource("mcl", initial_pose=f"{x} {y} {yaw}").plugins[0])
    plugin.setup()
    message = plugin.process({"odometry": lab_run.odometry[0], "ranges": lab_run.scans[0]}, Context(0, 0.0))
    assert message is not None
    assert np.hypot(message["x"] - x, message["y"] - y) < 0.3
    assert message["dispersion"] < 1.0
    with pytest.raises(ValueError, match="odometry"):
        plugin.process({"ranges": lab_run.scans[0]}, Context(1, 0.1))
    plugin.stop()


def test_a_frame_before_the_first_scan_or_odometry_publishes_nothing_and_is_no_error(lab_run: Run) -> None:
    plugin = Localization(_resource("mcl").plugins[0])
    plugin.setup()
    assert plugin.process({"odometry": lab_run.odometry[0], "ranges": None}, Context(0, 0.0)) is None
    assert plugin.process({"odometry": None, "ranges": lab_run.scans[0]}, Context(1, 0.1)) is None
    assert plugin.process({"scan": None, "odom": None}, Context(2, 0.2)) is None
    message = plugin.process({"odometry": lab_run.odometry[0], "ranges": lab_run.scans[0]}, Context(3, 0.3))
    assert message is not None and set(message) >= {"x", "y", "yaw"}
    plugin.stop()
