"""The world server applies a scenario (issue K point 3, D178): ``--scenario FILE`` (or
``$CKM_SIM_SCENARIO``) fires its events on the server's clock, logs them and keeps them in the run's
``sim-disturbances.json`` and ``sim-final.json``; a bad scenario stops the server at start with
FILE:LINE:COL. The server runs as its own process on 127.0.0.1, stopped in ``finally``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from plugins.sim.client import ENV_ADDRESS, ENV_KEY, Link
from plugins.sim.disturbances import ENV_SCENARIO
from plugins.sim.session import ServerProcess
from tests.waiting import until

CONFIG = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="disturbed">
  <Node name="rover">
    <HWChannel name="laser" direction="in" kind="stream" backend="sim" min="0" max="5" size="91">
      <Param name="body" value="rover"/>
      <Param name="pose" value="1.0 2.0 0"/>
      <Param name="sensor" value="lidar"/>
      <Param name="link" value="laser_link"/>
      <Param name="fov" value="1.5"/>
    </HWChannel>
  </Node>
  <Environment name="room" frame="map">
    <Map xmin="0" ymin="0" xmax="6" ymax="4" height="1.5"/>
  </Environment>
</System>
"""


@pytest.fixture
def config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    for name in (ENV_ADDRESS, ENV_KEY, ENV_SCENARIO):
        monkeypatch.delenv(name, raising=False)
    path = tmp_path / "disturbed.xml"
    path.write_text(CONFIG)
    return path


def test_the_server_fires_the_scenario_and_keeps_it_in_the_run(config: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "blocked.scenario"
    scenario.write_text("# a crate ahead of the rover\nat 0.3 add box crate 0.4 0.4 0.4 beside rover 1.0 0\n")
    run_dir = tmp_path / "run"
    server = ServerProcess(config, run_dir, options=["--render-workers", "0", "--scenario", str(scenario)])
    try:
        assert json.loads(server.ready.read_text())["scenario"] == str(scenario)
        link = Link(server.client_address())
        try:  # every request advances the world to the server's clock; the event fires past 0.3 s
            assert until(lambda: link.request({"op": "state"})["time"] > 0.5, timeout=30)
        finally:
            link.close()
        assert until(lambda: (run_dir / "sim-disturbances.json").is_file(), timeout=10)
    finally:
        assert server.stop() == 0
    fired = json.loads((run_dir / "sim-disturbances.json").read_text())
    assert [(f["line"], f["body"], f["event"]) for f in fired] == [
        (2, "crate", "at 0.3 add box crate 0.4 0.4 0.4 beside rover 1.0 0")
    ]
    assert fired[0]["time"] >= 0.3 and fired[0]["position"][:2] == pytest.approx([2.0, 2.0], abs=0.05)
    final = json.loads((run_dir / "sim-final.json").read_text())
    assert final["scenario"] == str(scenario) and final["disturbances"] == fired
    assert "disturbance at" in server.log.read_text()


def test_a_bad_scenario_stops_the_server_naming_where(config: Path, tmp_path: Path) -> None:
    scenario = tmp_path / "bad.scenario"
    scenario.write_text("at 1 move boulder by 1 0\n")
    with pytest.raises(RuntimeError, match=rf"{scenario}:1:11: no body 'boulder' in the world \(bodies: rover\)"):
        ServerProcess(config, tmp_path / "run", options=["--render-workers", "0", "--scenario", str(scenario)])
    scenario.write_text("at soon move rover by 1 0\n")
    with pytest.raises(RuntimeError, match=rf"{scenario}:1:4: a time \(s\) must be a number, not 'soon'"):
        ServerProcess(config, tmp_path / "run2", options=["--render-workers", "0", "--scenario", str(scenario)])
