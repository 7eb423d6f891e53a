"""The Nao's services in a closed loop with the simulated Nao (configs/usecase/nodes.xml's nao node).

The simulated top camera's frame goes, as the ``camera_raw`` Image, through ``plugin.naoqi-bridge``
(with the head angles the head sensors read) and the PanTiltCamera.Recog service's
``plugin.camera-acquisition``; a colour detector stands in for the ORB texture matching (it gives
the target's image centre as ``keypoint-matching`` does, in shares of the frame); its result and the
bridge's head state feed ``plugin.pan-tilt-track``, whose head goal the real ``pan-tilt-position``
controller (nodes.xml's Params) turns into the HeadYaw/HeadPitch position commands. The services see
only their messages; the physics is stepped here, in simulated time.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.controllers.pantilt import PanTiltPosition
from plugins.humanoid.naoqi import NaoQiBridge
from plugins.humanoid.track import PanTiltTrack
from plugins.processing.recognition import CameraAcquisition
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.world import World
from runtime.resources.spt import Context
from tests.conftest import CONFIGS
from tests.plugins.controllers.vector_records import record

RESOURCES = CONFIGS / "usecase" / "resources.xml"
CONTROL_STEPS = 4  # the head loop at 60 Hz on the 240 Hz physics
WIDTH, HEIGHT = 320, 240  # the camera rendered at QVGA (the Recog's initial scenario) to keep the test fast


NAO_HEAD = {"model": "nao", "panJoint": "HeadYaw", "tiltJoint": "HeadPitch", "camera": "CameraTop_optical_frame",
            "fov": 0.8331}
"""The Nao's head and camera, as configs/usecase/resources.xml gives them to its pan-tilt-track service."""


def plugin(cls: type[Any], kind: str, **params: object) -> Any:
    """A plugin declared in the use case's resources.xml (a pan-tilt-track with the Nao's head)."""
    given = tuple(Param(name=k, value=str(v))
                  for k, v in ({**NAO_HEAD, **params} if kind == "pan-tilt-track" else params).items())
    return cls(Plugin(name=kind, kind=kind, params=given, loc=Loc(str(RESOURCES), 1, 1, "/Plugin")))


def head_controller() -> PanTiltPosition:
    """nodes.xml's head_control."""
    return PanTiltPosition(record(
        "pan-tilt-position", 0.02, [("/nao/head_goal", "setpoint"), ("head_yaw_angle", "measure"),
                                    ("head_pitch_angle", "measure")], ["head_yaw_cmd", "head_pitch_cmd"], 10,
        kp=4.0, maxSpeed=2.0, panMin=-2.0857, panMax=2.0857, tiltMin=-0.6720, tiltMax=0.5149,
    ))


def detect(image: npt.NDArray[np.uint8], rgb: tuple[int, int, int], name: str) -> dict[str, Any]:
    """The pixels near colour ``rgb`` as a recognition result: their centre in shares of the frame."""
    rows, cols = image.shape[:2]
    close = np.abs(image.astype(int) - np.asarray(rgb)).max(axis=2) < 70
    count = int(close.sum())
    objects = []
    if count >= 20:
        ys, xs = np.nonzero(close)
        objects.append({"name": name, "x": float((xs.mean() + 0.5) / cols), "y": float((ys.mean() + 0.5) / rows),
                        "reliability": count / (count + 100.0)})
    mean = objects[0]["reliability"] if objects else 0.0
    return {"objects": objects, "reliability": mean, "width": cols, "height": rows}


class HeadLoop:
    """Camera → NaoQi bridge → acquisition → detector → Track → head controller → simulated joints."""

    def __init__(self, world: World, nao: Robot, pose: tuple[float, float, float], **track: object) -> None:
        self.world, self.nao = world, nao
        self.camera = Camera(nao, "CameraTop_optical_frame", fov=0.8331)
        self.yaw, self.pitch = nao.joint("HeadYaw"), nao.joint("HeadPitch")
        self.bridge: NaoQiBridge = plugin(NaoQiBridge, "naoqi-bridge")
        self.acquire: CameraAcquisition = plugin(CameraAcquisition, "camera-acquisition")
        self.track: PanTiltTrack = plugin(PanTiltTrack, "pan-tilt-track", pose=" ".join(map(str, pose)), **track)
        self.track.setup()
        self.controller = head_controller()
        self.goal: dict[str, float] | None = None
        self.frames = 0
        self.results: list[dict[str, Any]] = []
        self.goals: list[dict[str, float]] = []

    def angles(self) -> tuple[float, float]:
        return self.nao.joint_state(self.yaw)[0], self.nao.joint_state(self.pitch)[0]

    def control(self) -> None:
        pan, tilt = self.angles()
        commands = self.controller.step_outputs({"setpoint": self.goal, "measure[0]": pan, "measure[1]": tilt},
                                                CONTROL_STEPS * self.world.time_step)
        self.nao.command(self.yaw, "position", float(commands[0]))
        self.nao.command(self.pitch, "position", float(commands[1]))

    def frame(self, colour: tuple[int, int, int], name: str) -> dict[str, Any]:
        """One service period with the colour detector in the Recog's place."""

        def recognise(image: dict[str, Any]) -> dict[str, Any]:
            pixels = self.acquire.process(image, Context(self.frames, self.world.time, "PanTiltCamera"))
            return detect(pixels, colour, name)

        return self.recognised_by(recognise)

    def recognised_by(self, recognise: Callable[[dict[str, Any]], Any], size: tuple[int, int] = (WIDTH, HEIGHT)
                      ) -> dict[str, Any]:
        """One service period: a camera frame through the bridge, ``recognise`` (the bridge's Image to a
        Recog result) and the tracker."""
        now = self.world.time
        width, height = size
        shot = self.camera.render(width, height)
        raw = {"stamp": now, "width": width, "height": height, "encoding": "rgb8", "data": shot.rgb.tobytes()}
        pan, tilt = self.angles()
        bridged = self.bridge.process({"camera": raw, "head_yaw": pan, "head_pitch": tilt},
                                      Context(self.frames, now, "Nao"))
        recognised = recognise(bridged["image"])
        result = self.track.process({"objects": recognised, "head_state": bridged["head_state"]},
                                    Context(self.frames, now, "PanTiltCamera"))
        self.frames += 1
        if "head_goal" in result:
            self.goal = result["head_goal"]
            self.goals.append(result["head_goal"])
        self.results.append(result)
        return result

    def settle(self, seconds: float) -> None:
        """The head loop alone for ``seconds``."""
        for _ in range(round(seconds * 240 / CONTROL_STEPS)):
            self.control()
            self.world.step(CONTROL_STEPS)

    def run(self, seconds: float, colour: tuple[int, int, int], name: str, period: float = 0.5) -> None:
        """``seconds`` of simulated time, a service frame every ``period``."""
        for _ in range(round(seconds / period)):
            self.frame(colour, name)
            self.settle(period)

    def close(self) -> None:
        self.track.stop()
