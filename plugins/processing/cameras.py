"""The pinhole cameras of the perception plugins (thesis §7.4.1, the RGBDCamera's Asus Xtion).

One ``Camera`` per camera model: ``XTION`` is the intrinsics every depth and fusion plugin
defaults to (its ``fx fy cx cy calibrationWidth calibrationHeight`` Params) and the synthetic
renderer draws with. A configuration that simulates another lens names its own ``fx``/``fy``
(configs/usecase/resources.xml: 577.3 px, the simulated camera's field of view).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics given for a ``width`` × ``height`` image (default: Asus Xtion at VGA), and a pose."""

    fx: float = 525.0
    fy: float = 525.0
    cx: float = 319.5
    cy: float = 239.5
    width: int = 640
    height: int = 480
    elevation: float = 0.5  # metres above the floor (renderer only)
    tilt: float = 0.35  # radians pitched down (renderer only)

    def intrinsics(self, rows: int, cols: int) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) for a ``rows`` × ``cols`` image resampled from the reference size.

        Pixel centres map as in the resize plugin: pixel i of the small image sits at
        (i + 0.5)·factor − 0.5 of the reference one.
        """
        sx, sy = cols / self.width, rows / self.height
        return self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5


XTION = Camera()
"""The Asus Xtion's depth/RGB intrinsics at VGA (640 × 480): the default of every plugin's Params."""
