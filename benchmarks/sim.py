"""ckm-bench sim: the simulated laboratory's speed (issue J, thesis §7.1).

- ``world_steps_per_s``: physics steps per second of the use case's world (configs/usecase:
  environment, turtlebot and nao) with no sensor read.
- ``realtime_factor``: simulated seconds per wall second with both robots' devices at the use
  case's sensor and controller rates (read from configs/usecase/nodes.xml), each camera at the
  resolution its Smart Resource's TCM starts with (resources.xml: ``camera_resolution``). The
  RGB and depth streams of the Xtion share a render when their resolutions agree.
- ``per_resolution``: the same with every camera at VGA, QVGA and QQVGA, with the render cost.
- ``lockstep``: the real-time factor of a whole system in processes (node, world server, network)
  run by ``ckm-run --lockstep`` (:mod:`benchmarks.sim_lockstep`, D190, D192).

The cameras grab at the periods of the use case's Sensors, 0.5 s (D126), like the services that
consume them.

Physics at 240 Hz; each device acts at its own period on simulated time (no sleeping), so a
factor above 1 means the machine simulates faster than real time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ckm_lab.arm import Arm
from ckm_lab.devices import HOKUYO, KOBUKI, NAO_HEAD, XTION_FOV

import ckmconf
from ckmconf.model import System
from plugins.processing.textures import read_model
from plugins.sim.head import PanTiltHead
from plugins.sim.robots import DiffDriveBase, OdometryNoise, Robot
from plugins.sim.sensors import Camera, Lidar
from plugins.sim.world import World

from .sim_lockstep import lockstep_factor

USECASE = Path(__file__).resolve().parent.parent / "configs" / "usecase"
RESOLUTIONS = {"VGA": (640, 480), "QVGA": (320, 240), "QQVGA": (160, 120)}
TURTLEBOT_POSE = (7.6, 5.0, 1.5708)  # before the workbench, facing the objects
NAO_POSE = (5.5, 5.2, 0.0)


def _periods(system: System) -> dict[str, float]:
    """The period of every Sensor and Controller of the use case, by name."""
    periods: dict[str, float] = {}
    for node in system.nodes:
        periods.update({s.name: s.period for s in node.sensors})
        periods.update({c.name: c.period for c in node.controllers})
    return periods


def _initial(system: System) -> dict[str, str]:
    """The TCM's initial scenario of each service that has one, by ``Resource.Service`` name."""
    return {
        f"{resource.name}.{service.name}": service.tcm.initial
        for resource in system.resources
        for service in resource.services
        if service.tcm is not None and service.tcm.initial is not None
    }


def _lab() -> tuple[World, Robot, Robot]:
    system = ckmconf.load(USECASE / "lab.xml", strict=False).system
    assert system is not None and system.environment is not None
    world = World(system.environment, catalog=read_model(USECASE / "models" / "lab_objects_orb.yml"))
    turtlebot = Robot(world, "turtlebot", world.load_robot("turtlebot", "turtlebot", TURTLEBOT_POSE))
    nao = Robot(world, "nao", world.load_robot("nao", "nao", NAO_POSE))
    world.step(24)
    return world, turtlebot, nao


def world_steps(steps: int = 2400) -> float:
    """Physics steps per second of the lab world with both robots."""
    world, _, _ = _lab()
    start = time.perf_counter()
    world.step(steps)
    elapsed = time.perf_counter() - start
    world.close()
    return steps / elapsed


def realtime(cameras: dict[str, tuple[int, int]], periods: dict[str, float], duration: float) -> dict[str, Any]:
    """Simulate ``duration`` seconds with every device at its period; the factor and render cost."""
    world, turtlebot, nao = _lab()
    base = DiffDriveBase(turtlebot, **KOBUKI, noise=OdometryNoise(slip=0.02, seed=1))
    lidar = Lidar(turtlebot, "hokuyo_link", **HOKUYO, noise=0.01)
    xtion = Camera(turtlebot, "camera_rgb_optical_frame", fov=XTION_FOV)
    arm = Arm(turtlebot)
    top = Camera(nao, "CameraTop_optical_frame", fov=0.8331)
    head = PanTiltHead(nao, top, **NAO_HEAD)
    target = world.pose(world.objects["cylinder_red_stripes"])[0]
    render_time = [0.0, 0]

    def render(camera: Camera, size: tuple[int, int]) -> None:
        start = time.perf_counter()
        camera.render(*size)
        render_time[0] += time.perf_counter() - start
        render_time[1] += 1

    def xtion_frames() -> None:
        render(xtion, cameras["xtion_rgb"])
        if cameras["xtion_depth"] != cameras["xtion_rgb"]:
            render(xtion, cameras["xtion_depth"])

    poses = iter(["rest", "pre-grasp", "lift", "carry"] * 1000)
    devices: list[tuple[float, Callable[[], Any]]] = [
        (periods["left_wheel"], lambda: base.ticks()),
        (periods["left_pid"], lambda: base.drive(0.05, 0.1)),
        (periods["odometry"], base.update),
        (periods["lidar"], lidar.scan),
        (periods["rgb_camera"], xtion_frames),
        (periods["arm_joints"], lambda: [turtlebot.joint_state(j) for j in arm.joints]),
        (1.0, lambda: arm.go(next(poses))),
        (periods["head_yaw_sensor"], lambda: (nao.joint_state(head.yaw), nao.joint_state(head.pitch))),
        (periods["head_control"], lambda: head.track(target)),
        (periods["top_camera"], lambda: render(top, cameras["nao_top"])),
    ]
    releases = [0.0] * len(devices)
    start = time.perf_counter()
    while world.time < duration:
        for index, (period, act) in enumerate(devices):
            if releases[index] <= world.time + 1e-9:
                act()
                releases[index] += period
        world.step()
    elapsed = time.perf_counter() - start
    world.close()
    renders = render_time[1]
    return {
        "realtime_factor": round(duration / elapsed, 3),
        "renders": renders,
        "render_ms": round(1000 * render_time[0] / renders, 2) if renders else 0.0,
        "render_share": round(render_time[0] / elapsed, 3),
    }


def run(duration: float = 3.0, lockstep_s: float = 20.0) -> dict[str, Any]:
    """The figures of the module docstring; ``duration`` simulated seconds per configuration, and
    ``lockstep_s`` simulated seconds of the lock-step run of a whole system (0: none)."""
    system = ckmconf.load(USECASE / "lab.xml", strict=False).system
    assert system is not None
    periods = _periods(system)
    initial = _initial(system)
    chosen = {
        "xtion_rgb": initial["RGBDCamera.RGBRecog"],
        "xtion_depth": initial["RGBDCamera.DepthRecog"],
        "nao_top": initial["PanTiltCamera.Recog"],
    }
    result: dict[str, Any] = {"world_steps_per_s": round(world_steps(), 1), "duration_s": duration}
    tcm = realtime({k: RESOLUTIONS[v] for k, v in chosen.items()}, periods, duration)
    result.update(realtime_factor=tcm["realtime_factor"], camera_resolution=chosen, render_ms=tcm["render_ms"])
    result["per_resolution"] = [
        {"resolution": name, **realtime(dict.fromkeys(chosen, size), periods, duration)}
        for name, size in RESOLUTIONS.items()
    ]
    result["periods_s"] = {k: periods[k] for k in ("left_wheel", "lidar", "rgb_camera", "top_camera", "head_control")}
    if lockstep_s > 0:
        result["lockstep"] = lockstep_factor(duration=lockstep_s)
    return result


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """Rows of the human table."""
    chosen = ", ".join(f"{k} {v}" for k, v in result["camera_resolution"].items())
    rows = [
        ("world alone", f"{result['world_steps_per_s']:.0f} steps/s (240 steps per simulated s)"),
        (f"real-time factor ({chosen})", f"{result['realtime_factor']:.2f}× (render {result['render_ms']} ms)"),
    ]
    for row in result["per_resolution"]:
        cost = f"render {row['render_ms']} ms, {row['render_share']:.0%} of the time"
        rows.append((f"real-time factor, every camera {row['resolution']}", f"{row['realtime_factor']:.2f}× ({cost})"))
    if "lockstep" in result:
        run = result["lockstep"]
        rows.append((f"ckm-run --lockstep {run['step_s']} of {run['system']} (processes, network, world server)",
                     f"{run['factor']:.2f}× ({run['simulated_s']} s simulated in {run['wall_s']} s wall, "
                     f"{run['startup_wall_s']} s of it start-up)"))
    return rows
