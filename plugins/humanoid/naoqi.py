"""``plugin.naoqi-bridge``: the Nao.NaoQi service (thesis §7.1, Table 7.2, Fig. 7.7).

The thesis wraps the NaoQi calls as ROS topics so the Nao's camera and head reach the RMPA network.
This SPT service plugin does that on the Nao node's raw topics (the lab's ``Nao.NaoQi`` service),
with the inputs ``{input name: newest value or None}``:

- ``camera`` (Image, ``camera_raw``): the top camera frame as the simulated (or real) sensor
  publishes it, ``{"stamp", "width", "height", "encoding", "data": bytes}`` (D99);
- ``head_yaw``, ``head_pitch`` (float64, ``head_yaw_angle``/``head_pitch_angle``): the head joints.

Outputs: ``image`` (Image, each new frame once: what ``plugin.camera-acquisition`` of the
PanTiltCamera.Recog service reads — width, height, encoding, bytes data), ``head_state``
(PanTilt ``{"pan": yaw, "tilt": pitch}``), ``status`` (NaoStatus ``{"stamp", "available",
"camera", "head", "error"}``) and the measure ``available`` (Table 7.2): 1 while the camera and
the head inputs are live and readable, 0 when one goes stale (no new sample for ``timeout``
seconds) or is malformed.

Staleness (D112). The stream hands the plugin the newest value of each input whenever any input
has a fresh sample, without saying which. A camera frame is new when its ``stamp`` changes; the
head is live when its angles change or when a frame comes without a new camera frame (then a head
sample triggered it). That needs the service's period shorter than the camera's (the default
1/30 s against the simulated Nao camera's 0.5 s, D126). NaoQi's battery and stiffness are not simulated: the
status leaves them out.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import MAPPING, NUMBER, P, Params, Ports

CHANNELS: Mapping[str, int] = {"rgb8": 3, "bgr8": 3, "mono8": 1}


class NaoQiBridge(ProcessingPlugin):
    """The Nao's camera and head as service outputs, with their availability (see the module docstring)."""

    PORTS = Ports(inputs={"camera": MAPPING, "head_yaw": NUMBER, "head_pitch": NUMBER, "*": MAPPING},
                  outputs={"*": MAPPING})  # an Image and two angles in; Image, PanTilt, NaoStatus out
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("timeout", 1.5, "Age after which an input without new samples is stale (three periods of the use "
          "case's simulated camera, D126).", unit="s", above=0.0),
        P("encoding", "rgb8", "Encoding of frames that name none: rgb8, bgr8 or mono8.", choices=tuple(CHANNELS)),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if self.params["encoding"] not in CHANNELS:
            raise ParamError(f"{self.owner}: parameter 'encoding' = {self.params['encoding']!r} is not one of "
                             f"{', '.join(CHANNELS)}")
        self._frame: Any = None  # the last frame's stamp (its data when it has none)
        self._camera_seen: float | None = None
        self._head: tuple[float, float] | None = None
        self._head_seen: float | None = None

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The image (once per new frame), head state, status and ``available`` measure (Table 7.2).

        Raises:
            ValueError: ``data`` is not a mapping of the inputs.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'camera', 'head_yaw', 'head_pitch'}}, got {type(data).__name__}")
        now = context.stamp
        errors: list[str] = []
        result: dict[str, Any] = {}
        image, problem = self._image(data.get("camera"))
        new_frame = False
        if problem:
            errors.append(problem)
        elif image is not None and (image["stamp"] if image["stamp"] is not None else image["data"]) != self._frame:
            new_frame, self._camera_seen = True, now
            self._frame = image["stamp"] if image["stamp"] is not None else image["data"]
            result["image"] = image
        head, problem = self._angles(data.get("head_yaw"), data.get("head_pitch"))
        if problem:
            errors.append(problem)
        elif head is not None:
            if head != self._head or not new_frame:  # a head sample triggered this frame, or the head moved
                self._head_seen = now
            self._head = head
            result["head_state"] = {"pan": head[0], "tilt": head[1]}
        timeout = self.params["timeout"]
        camera_live = self._camera_seen is not None and now - self._camera_seen <= timeout
        head_live = self._head_seen is not None and now - self._head_seen <= timeout
        if not camera_live and not errors:
            errors.append("no camera frame" if self._camera_seen is None else
                          f"camera stale: no new frame for {now - self._camera_seen:.2f} s")
        if not head_live and not errors:
            errors.append("no head angles" if self._head_seen is None else
                          f"head stale: no new angles for {now - self._head_seen:.2f} s")
        available = camera_live and head_live and not errors
        result["status"] = {"stamp": now, "available": available, "camera": camera_live, "head": head_live,
                            "error": "; ".join(errors)}
        result["available"] = 1 if available else 0
        return result

    def _image(self, message: Any) -> tuple[dict[str, Any] | None, str]:
        """The frame as an Image message for camera-acquisition, or why it is not one."""
        if message is None:
            return None, ""
        if not isinstance(message, Mapping):
            return None, f"camera frame is {type(message).__name__}, not an Image"
        width, height, raw = message.get("width"), message.get("height"), message.get("data")
        encoding = str(message.get("encoding") or self.params["encoding"])
        if encoding not in CHANNELS:
            return None, f"camera frame encoding {encoding!r} is not one of {', '.join(CHANNELS)}"
        sizes = (width, height)
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and int(v) > 0 for v in sizes):
            return None, f"camera frame size {width!r} x {height!r} is not two positive integers"
        if not isinstance(raw, bytes | bytearray | memoryview):
            return None, f"camera frame data is {type(raw).__name__}, not bytes"
        width, height = int(width), int(height)  # type: ignore[arg-type]
        expected = width * height * CHANNELS[encoding]
        if len(raw) != expected:
            return None, f"camera frame {encoding} {width}x{height} needs {expected} bytes, got {len(raw)}"
        stamp = message.get("stamp")
        return {"stamp": stamp if isinstance(stamp, int | float) else None, "width": width, "height": height,
                "encoding": encoding, "data": bytes(raw)}, ""

    @staticmethod
    def _angles(yaw: Any, pitch: Any) -> tuple[tuple[float, float] | None, str]:
        if yaw is None or pitch is None:
            return None, ""
        values = []
        for name, value in (("head_yaw", yaw), ("head_pitch", pitch)):
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                return None, f"{name} = {value!r} is not a finite angle"
            values.append(float(value))
        return (values[0], values[1]), ""
