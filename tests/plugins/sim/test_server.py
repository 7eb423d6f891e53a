"""One simulated world for every process of a run (issue J point 5, D100–D103).

A world server (``python -m plugins.sim.server``) holds the pybullet world; ``hardware.sim``
channels of any process are its clients. A partition process of ``ckm-run`` drives the rover while
this test process measures it with its own lidar client; a killed server fails the run loudly
(exit 5, message on stderr); malformed requests get errors naming the channel and the server lives
on; the world plan is read from the channels; the client-mode device gives the in-process reading.
Every process started here is killed in ``finally``; everything listens on 127.0.0.1.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from multiprocessing import Pipe
from multiprocessing.connection import Client
from pathlib import Path

import numpy as np
import psutil
import pytest

import ckmconf
from ckmconf import ConfigError
from ckmconf.model import HWChannel, Param
from plugins.hardware.sim import SimBackend
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from plugins.sim.client import ENV_ADDRESS, ENV_KEY, Link, RemoteDevice
from plugins.sim.devices import SimWorld
from plugins.sim.plan import WorldPlan
from plugins.sim.render import RenderWorker
from plugins.sim.server import WorldServer
from plugins.sim.serving import Client as ServedClient
from plugins.sim.session import READY, ServerProcess, world_session
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network
from tests.waiting import until

CONFIG = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="shared-world">
  <Node name="rover">
    <Partition name="drive" restart="never"/>
    <Partition name="sense" restart="never"/>
    <HWChannel name="left_motor" direction="out" kind="pwm" backend="sim" min="-1" max="1">
      <Param name="body" value="rover"/>
      <Param name="pose" value="2.0 2.0 0"/>
      <Param name="joint" value="left_wheel_joint"/>
      <Param name="mode" value="velocity"/>
      <Param name="maxVelocity" value="8"/>
    </HWChannel>
    <HWChannel name="right_motor" direction="out" kind="pwm" backend="sim" min="-1" max="1">
      <Param name="body" value="rover"/>
      <Param name="joint" value="right_wheel_joint"/>
      <Param name="mode" value="velocity"/>
      <Param name="maxVelocity" value="8"/>
    </HWChannel>
    <HWChannel name="left_encoder" direction="in" kind="counter" backend="sim">
      <Param name="body" value="rover"/>
      <Param name="joint" value="left_wheel_joint"/>
      <Param name="ticksPerRev" value="1024"/>
    </HWChannel>
    <HWChannel name="laser" direction="in" kind="stream" backend="sim" min="0" max="5" size="91">
      <Param name="body" value="rover"/>
      <Param name="sensor" value="lidar"/>
      <Param name="link" value="laser_link"/>
      <Param name="fov" value="1.5"/>
    </HWChannel>
    <HWChannel name="wrist" direction="in" kind="stream" backend="sim" units="mm" size="4800">
      <Param name="body" value="turtlebot"/>
      <Param name="pose" value="4.5 2.0 3.1416"/>
      <Param name="sensor" value="depth"/>
      <Param name="link" value="camera_depth_optical_frame"/>
      <Param name="width" value="80"/>
      <Param name="height" value="60"/>
      <Param name="fov" value="1.0123"/>
    </HWChannel>
    <Topic name="wheel_speed" type="float64" scope="internal"/>
    <Topic name="wrist_depth" type="float64" scope="internal"/>
    <Topic name="drive_left" type="float64" scope="internal"/>
    <Topic name="drive_right" type="float64" scope="internal"/>
    <Topic name="nearest" type="float64" scope="internal"/>
    <Sensor name="left_wheel" channel="left_encoder" topic="wheel_speed" period="0.02" partition="drive"/>
    <Sensor name="lidar" channel="laser" topic="nearest" period="0.1" extrapolation="none" partition="sense"/>
    <Sensor name="wrist" channel="wrist" topic="wrist_depth" period="0.5" extrapolation="none" partition="sense"/>
    <Controller name="left_duty" kind="constant" period="0.02" partition="drive">
      <Param name="value" value="0.5"/><Input topic="wheel_speed" role="measure"/><Output topic="drive_left"/>
    </Controller>
    <Controller name="right_duty" kind="constant" period="0.02" partition="drive">
      <Param name="value" value="0.5"/><Input topic="wheel_speed" role="measure"/><Output topic="drive_right"/>
    </Controller>
    <Actuator name="left" channel="left_motor" topic="drive_left" min="-1" max="1" safeValue="0" partition="drive"/>
    <Actuator name="right" channel="right_motor" topic="drive_right" min="-1" max="1" safeValue="0" partition="drive"/>
  </Node>
  <Environment name="room" frame="map">
    <Map xmin="0" ymin="0" xmax="6" ymax="4" height="1.5"/>
  </Environment>
</System>
"""
EXIT_FAILED = 5  # docs/exit-codes.md: something failed while running
AHEAD = 45  # the lidar beam straight ahead (91 beams over 1.5 rad)
STARTUP = 90.0  # s: bound on a run's processes coming up (seconds when quiet; the 2 cores are shared)


@pytest.fixture
def config(tmp_path: Path) -> Path:
    """The test system on a private loopback network."""
    system = ckmconf.load_bytes(CONFIG.encode(), str(tmp_path / "template.xml"))
    path = tmp_path / "shared_world.xml"
    ckmconf.dump(dataclasses.replace(system, network=private_network()), path)
    return path


@pytest.fixture
def no_server(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ENV_ADDRESS, raising=False)
    monkeypatch.delenv(ENV_KEY, raising=False)


def channel_of(config: Path, name: str) -> HWChannel:
    return next(ch for ch in ckmconf.load(config).nodes[0].channels if ch.name == name)


@contextlib.contextmanager
def ckm_run(config: Path, run_dir: Path, env: dict[str, str]) -> Iterator[subprocess.Popen[bytes]]:
    """ckm-run of ``config`` (its output in RUN_DIR.out); it and its children are killed at the end."""
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    with (run_dir.parent / f"{run_dir.name}.out").open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "runtime.cli", str(config), "--log-dir", str(run_dir)],
            cwd=REPO,
            stdout=subprocess.DEVNULL,
            stderr=out,
            env=env,
        )
    seen: list[psutil.Process] = []
    try:
        yield process
    finally:
        with contextlib.suppress(psutil.Error):
            seen = psutil.Process(process.pid).children(recursive=True)
        process.kill()
        process.wait(timeout=10)
        for child in seen:
            with contextlib.suppress(psutil.Error):
                child.kill()


def partitions_running(run_dir: Path) -> bool:
    logs = [run_dir / name / "ckm.log" for name in ("drive", "sense")]
    return all(log.is_file() and "INFO ckm.run: running" in log.read_text() for log in logs)


def test_a_partition_drives_the_robot_that_another_process_measures(
    config: Path, tmp_path: Path, no_server: None
) -> None:
    with ServerProcess(config, tmp_path / "server") as server:
        env = {**os.environ, **server.environ()}  # a server named already: ckm-run uses it, starts none
        run_dir = tmp_path / "run"
        with ckm_run(config, run_dir, env) as run:
            laser = RemoteDevice(server.client_address(), SimBackend(channel_of(config, "laser")).spec())
            link = Link(server.client_address())
            try:

                def sample() -> tuple[float, float]:
                    ranges = laser.read()
                    x = link.request({"op": "state"})["robots"]["rover"][0]
                    return float(ranges[AHEAD]), float(x)  # type: ignore[index]

                start_range, start_x = sample()
                assert until(lambda: sample()[1] - start_x > 0.4, STARTUP), "the drive partition did not move the rover"
                now_range, now_x = sample()
                # this process's lidar sees the wall come nearer by what the partition drove
                assert start_range - now_range == pytest.approx(now_x - start_x, abs=0.05)
                assert partitions_running(run_dir)
            finally:
                laser.close()
                link.close()
            run.send_signal(signal.SIGTERM)
            assert run.wait(timeout=60) == 0, (tmp_path / "run.out").read_text()
        assert not (run_dir / READY).exists()  # it started no server of its own
        log = server.log.read_text()
        assert log.count("connected") >= 7  # this test's two links, the partitions' five channels
        assert "render worker" not in log  # no render fell back to the physics thread


def test_a_killed_world_server_fails_the_run_loudly(config: Path, tmp_path: Path, no_server: None) -> None:
    run_dir = tmp_path / "run"
    with ckm_run(config, run_dir, dict(os.environ)) as run:
        assert until(lambda: (run_dir / READY).is_file() and partitions_running(run_dir), STARTUP), "no run started"
        pid = json.loads((run_dir / READY).read_text())["pid"]
        os.kill(pid, signal.SIGKILL)
        code = run.wait(timeout=60)
    stderr = (tmp_path / "run.out").read_text()
    assert code == EXIT_FAILED, stderr
    assert f"the simulated world server (pid {pid}) was killed by signal 9" in stderr
    assert "stopping the run" in stderr


def test_bad_requests_get_errors_naming_the_channel(config: Path, tmp_path: Path, no_server: None) -> None:
    with ServerProcess(config, tmp_path / "server") as server:
        silent = socket.create_connection(("127.0.0.1", server.client_address()[1]), timeout=5.0)
        link = Link(server.client_address())  # a peer that never answers the handshake blocks no one
        try:
            with pytest.raises(ValueError, match="bad request"):
                link.exchange(b"\xff{not json")
            with pytest.raises(ValueError, match="JSON object"):
                link.exchange(b"[1, 2]")
            with pytest.raises(ValueError, match="unknown op 'fly'"):
                link.request({"op": "fly"})
            with pytest.raises(ValueError, match="no channel open with handle 7"):
                link.request({"op": "read", "handle": 7})
            spec = SimBackend(channel_of(config, "left_encoder")).spec().to_dict()
            wrong = {**spec, "name": "enc", "values": {**spec["values"], "joint": "no_such_joint"}}
            with pytest.raises(KeyError, match="sim channel 'enc': robot 'rover' has no joint 'no_such_joint'"):
                link.request({"op": "open", "spec": wrong})
            with pytest.raises(ValueError, match="sim channel 'odd': kind 'torque'"):
                link.request({"op": "open", "spec": {**spec, "name": "odd", "kind": "torque"}})
            handle = link.request({"op": "open", "spec": spec})["handle"]
            with pytest.raises(ValueError, match="sim channel 'left_encoder' is an input channel"):
                link.request({"op": "write", "handle": handle, "value": 1.0})
            assert isinstance(link.request({"op": "read", "handle": handle})["value"], float)
            motor = SimBackend(channel_of(config, "left_motor")).spec().to_dict()
            out = link.request({"op": "open", "spec": motor})["handle"]
            # an actuator's write is silent: a bad one is answered, and raised by the next exchange
            link.request({"op": "write", "handle": out, "value": "fast", "reply": False}, answer=False)
            with pytest.raises(ValueError, match="sim channel 'left_motor': write needs a number"):
                link.request({"op": "ping"})
            link.request({"op": "write", "handle": out, "value": 0.25, "reply": False}, answer=False)
            assert link.request({"op": "ping"})["time"] >= 0.0  # a silent write that worked answers nothing
            with pytest.raises(ConnectionError):  # a request over 1 MiB: that connection is dropped…
                Link(server.client_address()).exchange(b" " * (2 << 20))
            with pytest.raises(Exception, match="digest"):  # …a client without the key is refused…
                Client(("127.0.0.1", server.client_address()[1]), authkey=b"wrong key")
            assert link.request({"op": "ping"})["time"] >= 0.0  # …and the server serves on
        finally:
            link.close()
            silent.close()
        assert server.process.poll() is None
    assert "stopped after" in server.log.read_text()


def test_client_mode_reads_what_the_in_process_world_reads(
    config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, no_server: None
) -> None:
    with plant_scope(PlantScope(ManualClock(), name="in-process")):
        local = [SimBackend(channel_of(config, name)) for name in ("left_motor", "laser", "wrist")]
    for backend in local:
        backend.setup()
    ranges, depth = local[1].read(), local[2].read()
    wrist = channel_of(config, "wrist")
    stray = dataclasses.replace(
        wrist,
        name="stray",
        params=tuple(  # a robot the plan did not load
            Param(name=k, value=v)
            for k, v in (
                ("body", "station_arm"),
                ("pose", "1 3 0"),
                ("sensor", "depth"),
                ("link", "wrist_camera_optical_frame"),
                ("width", "80"),
                ("height", "60"),
                ("fov", "1.5184"),
            )
        ),
    )
    with ServerProcess(config, tmp_path / "server") as server:
        monkeypatch.setenv(ENV_ADDRESS, server.address)
        monkeypatch.setenv(ENV_KEY, server.key.hex())
        remote = [SimBackend(record) for record in (channel_of(config, "laser"), wrist)]
        for backend in remote:
            backend.setup()
        try:
            assert all(b.remote is not None and b.sim is None for b in remote)  # client mode: no world here
            served_ranges, served_depth = remote[0].read(), remote[1].read()  # the depth: by the render worker
            strayed = SimBackend(stray)
            strayed.setup()
            away = strayed.read()  # the worker's mirror has no station arm: the server renders it itself
            strayed.stop()
        finally:
            for backend in remote:
                backend.stop()
        log = server.log.read_text()
    assert isinstance(served_ranges, np.ndarray) and isinstance(ranges, np.ndarray) and served_ranges.shape == (91,)
    assert served_ranges == pytest.approx(ranges, abs=0.002)  # the same device code on the same world
    assert isinstance(served_depth, np.ndarray) and isinstance(depth, np.ndarray) and served_depth.shape == (4800,)
    assert min(depth) < 5000  # it sees something: the rover, the floor, the walls
    differences = [abs(a - b) for a, b in zip(served_depth, depth, strict=True)]
    assert sum(differences) / len(differences) < 5.0  # mm: the mirror's render is the world's
    assert isinstance(away, np.ndarray) and away.shape == (4800,) and away.min() > 0.0
    assert "this camera renders in the physics thread" in log


def test_the_plan_follows_the_channels_and_refuses_two_worlds(config: Path, tmp_path: Path) -> None:
    plan = WorldPlan.of(list(ckmconf.load(config).nodes))
    assert plan is not None and plan.world == str(config.resolve())
    # the first channel giving a pose places each robot
    assert plan.bodies == {"rover": ("", "2.0 2.0 0"), "turtlebot": ("", "4.5 2.0 3.1416")}
    other = tmp_path / "other.xml"
    other.write_text(config.read_text())
    text = (
        config.read_text()
        .replace(
            '<Param name="joint" value="right_wheel_joint"/>',
            '<Param name="joint" value="right_wheel_joint"/><Param name="world" value="other.xml"/>',
            1,
        )
        .replace(
            '<Param name="pose" value="2.0 2.0 0"/>',
            '<Param name="pose" value="2.0 2.0 0"/><Param name="world" value="shared_world.xml"/>',
            1,
        )
    )
    two = tmp_path / "two_worlds.xml"
    two.write_text(text)
    with pytest.raises(ConfigError, match=r"right_motor.*a run has one simulated world"):
        WorldPlan.of(list(ckmconf.load(two).nodes))


def test_a_session_starts_nothing_when_a_server_is_named_or_nothing_is_simulated(
    config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    system = ckmconf.load(config)
    failures: list[str] = []
    monkeypatch.setenv(ENV_ADDRESS, "off")
    with world_session(system, config, tmp_path / "a", system.nodes, failures.append):
        assert os.environ[ENV_ADDRESS] == "off"
    monkeypatch.delenv(ENV_ADDRESS)
    bare = dataclasses.replace(system.nodes[0], channels=())
    with world_session(system, config, tmp_path / "b", [bare], failures.append):
        assert ENV_ADDRESS not in os.environ
    assert not (tmp_path / "a" / READY).exists() and not (tmp_path / "b" / READY).exists() and not failures


def test_a_node_run_session_names_its_files_and_cleans_up(config: Path, tmp_path: Path, no_server: None) -> None:
    system = ckmconf.load(config)
    other = dataclasses.replace(system.nodes[0], name="other", channels=())
    wider = dataclasses.replace(system, nodes=(*system.nodes, other))  # as if run with --node rover
    failures: list[str] = []
    run_dir = tmp_path / "run"
    with world_session(wider, config, run_dir, system.nodes, failures.append):
        ready = json.loads((run_dir / "sim-server-rover.json").read_text())  # a --node run's own files (D64)
        assert os.environ[ENV_ADDRESS] == ready["address"] and ready["robots"] == ["rover", "turtlebot"]
        host, _, port = ready["address"].rpartition(":")
        link = Link((host, int(port), bytes.fromhex(os.environ[ENV_KEY])))
        assert link.request({"op": "ping"})["time"] >= 0.0
        link.close()
    assert ENV_ADDRESS not in os.environ and ENV_KEY not in os.environ
    assert not psutil.pid_exists(ready["pid"])  # stopped and reaped
    assert not failures  # a server stopped at the end is no failure
    assert not (run_dir / READY).exists()
    final = json.loads((run_dir / "sim-final-rover.json").read_text())  # where the robots left the world
    assert set(final["positions"]) >= {"rover", "turtlebot"} and final["time"] >= 0.0
    assert all(len(xyz) == 3 for xyz in final["positions"].values())


def test_the_rgb_and_depth_reads_of_one_viewpoint_at_one_step_are_one_render(config: Path) -> None:
    """D240: the Xtion's RGB and depth optical frames coincide. A depth read made while the RGB read's
    frame is in flight joins it; one made after it landed, at the same step, is served from it."""
    depth = channel_of(config, "wrist")
    rgb = dataclasses.replace(depth, name="wrist_rgb", size=14400, params=tuple(
        Param(name=p.name, value={"sensor": "rgb", "link": "camera_rgb_optical_frame"}.get(p.name, p.value))
        for p in depth.params
    ))  # fmt: skip
    plan = WorldPlan.of(list(ckmconf.load(config).nodes))
    assert plan is not None
    sim = SimWorld(lambda: 0.0, None, plan.seed, plan.textures, plan.world)  # a clock that stands still
    for name, (model, pose) in plan.bodies.items():
        sim.robot(name, model, pose)
    worker = RenderWorker(plan)
    server = WorldServer(sim, b"test key", renderers=[worker])
    near, far = Pipe()
    client = ServedClient(1, far)
    server.clients.append(client)
    try:
        assert worker.await_ready(STARTUP)
        devices = [client.devices[server._open(client, SimBackend(c).spec())] for c in (rgb, depth)]
        assert devices[0].camera == devices[1].camera  # one viewpoint, field of view and size
        for device in devices:  # the depth read comes while the colour frame is being made
            server._cameras.append((client, device))
            server._dispatch()
        assert [len(f.waiters) for f in server._flights.values()] == [2]
        server._landed(worker)
        colour, depth_mm = (near.recv()["value"] for _ in devices)
        assert colour.shape == (60, 80, 3) and depth_mm.shape == (60, 80) and depth_mm.min() > 0
        server._cameras.append((client, devices[1]))  # again, at the same step: the frame kept
        server._dispatch()
        assert not server._flights and worker.busy is False
        assert np.array_equal(near.recv()["value"], depth_mm)
    finally:
        server.close()
        sim.world.close()
