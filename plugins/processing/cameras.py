"""The pinhole cameras of the perception plugins (thesis §7.4.1).

A ``Camera`` holds one camera's intrinsics at the image size they were calibrated for. The depth
and fusion plugins take theirs from the configuration (``fx`` and ``calibrationWidth`` ×
``calibrationHeight`` are required; ``fy``, ``cx``, ``cy`` default to square pixels and the
image's centre, :meth:`Camera.pinhole`): the frames that reach them (arrays after the acquisition
and resize plugins, Image/DepthImage messages) carry no intrinsics, and no lab's camera is a
default (D261).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from runtime.kernel.interfaces import ParamError


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics given for a ``width`` × ``height`` image, and a pose (renderer only)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    elevation: float = 0.5  # metres above the floor (renderer only)
    tilt: float = 0.35  # radians pitched down (renderer only)

    @classmethod
    def pinhole(
        cls, fx: float, width: int, height: int, *, fy: float | None = None, cx: float | None = None,
        cy: float | None = None,
    ) -> Camera:
        """The camera of focal length ``fx`` at ``width`` × ``height``; what is not given is the ideal
        pinhole's: square pixels (``fy`` = ``fx``), the principal point at the image's centre
        ((width − 1)/2, (height − 1)/2, pixel centres at whole coordinates), as a simulated camera renders."""
        return cls(
            fx,
            fx if fy is None else fy,
            (width - 1) / 2 if cx is None else cx,
            (height - 1) / 2 if cy is None else cy,
            width,
            height,
        )

    def intrinsics(self, rows: int, cols: int) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) for a ``rows`` × ``cols`` image resampled from the reference size.

        Pixel centres map as in the resize plugin: pixel i of the small image sits at
        (i + 0.5)·factor − 0.5 of the reference one.
        """
        sx, sy = cols / self.width, rows / self.height
        return self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5


def camera_of(params: Mapping[str, Any], owner: str) -> Camera:
    """The camera of a plugin's Params ``fx fy cx cy calibrationWidth calibrationHeight`` (``fx`` and
    the size given; ``fy``, ``cx``, ``cy`` None: the ideal pinhole's, :meth:`Camera.pinhole`).

    Raises:
        ParamError: a value is not finite, or a focal length or the size is not positive.
    """
    for name in ("fx", "fy", "cx", "cy"):
        value = params[name]
        if value is not None and not math.isfinite(value):
            raise ParamError(f"{owner}: parameter {name!r} = {value} is not finite")
    for name in ("fx", "fy", "calibrationWidth", "calibrationHeight"):
        if params[name] is not None and not params[name] > 0:
            raise ParamError(f"{owner}: parameter {name!r} = {params[name]} must be greater than 0")
    return Camera.pinhole(
        params["fx"], params["calibrationWidth"], params["calibrationHeight"],
        fy=params["fy"], cx=params["cx"], cy=params["cy"],
    )

