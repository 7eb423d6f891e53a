"""``plugin.localization``: the Navigation service's localization as an SPT processing plugin (§6.2.1, Table 7.1).

Each frame brings the odometry reading and a laser scan; the plugin runs one step of the selected
filter — ``filter=reliability`` (Algorithm 3) or ``filter=mcl`` (the AMCL-like baseline) — and
returns the PoseEstimate: the pose, its 3×3 covariance and the localization dispersion, the
quality measure of the use case's AMCL service (``localization_dispersion``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

import ckmconf
from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, NUMBERS, REQUIRED, P, Params, Ports

from .mcl import AmclFilter, MclSettings
from .raster import GridMap
from .raycast import LaserSpec
from .reliability_filter import ReliabilityFilter, ReliabilitySettings

Array = npt.NDArray[np.float64]


def _pose(text: str, owner: str) -> Array | None:
    if not text.strip():
        return None
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3:
        raise ParamError(f"{owner}: parameter 'initial_pose' = {text!r} is not 'x y yaw'")
    return np.array(values)


class Localization(ProcessingPlugin):
    """``plugin.localization``: one filter step per frame ``{"odometry": (x, y, yaw), "ranges": [...]}``.

    Returns ``{"x", "y", "yaw", "covariance" (9 floats, row-major), "dispersion", "filter",
    "reliability"}``; ``reliability`` is R of eq. 6.21 for Algorithm 3 and None for MCL.
    """

    PORTS = Ports(inputs={"odometry": NUMBERS, "ranges": NUMBERS, "*": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "localization"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"pose": ("x", "y", "yaw", "covariance", "dispersion", "filter",
                                                                "reliability")}
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P(
            "filter",
            "reliability",
            "Algorithm 3 ('reliability') or the AMCL-like baseline ('mcl').",
            choices=("reliability", "mcl"),
        ),
        P("particles", 2500, "Number of particles (MCL: the maximum with KLD sampling).", min=10),
        P("environment", REQUIRED, "XML file holding the system's <Environment> (the map), relative to the "
          "configuration file.", type=str, file=ENVIRONMENT_FILE),
        P("resolution", 0.05, "Grid cell size of the map.", unit="m", above=0.0),
        P("fov", 2 * np.pi, "Laser field of view, beams spread evenly over it.", unit="rad", above=0.0),
        P("max_range", 8.0, "Laser maximum range: beams at it hit nothing.", unit="m", above=0.0),
        P("initial_pose", "", "'x y yaw' to start around, empty for global localization."),
        P("kld", False, "MCL only: KLD sampling of the particle count."),
        P("seed", 0, "Random seed of the filter.", min=0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.initial = _pose(self.params["initial_pose"], self.owner)
        self.grid: GridMap | None = None
        self.filter: AmclFilter | ReliabilityFilter | None = None
        self.beams = 0

    def setup(self) -> None:
        """Load the environment and rasterise it."""
        path = config_dir(self.record) / self.params["environment"]
        env = ckmconf.load(path).environment
        if env is None:
            raise ParamError(f"{self.owner}: {path} holds no <Environment>")
        self.grid = GridMap.from_environment(env, self.params["resolution"])

    def _build(self, beams: int) -> AmclFilter | ReliabilityFilter:
        if self.grid is None:
            self.setup()
        assert self.grid is not None
        p = self.params
        angles = LaserSpec(beams=beams, fov=p["fov"], max_range=p["max_range"]).angles()
        rng = np.random.default_rng(p["seed"])
        built: AmclFilter | ReliabilityFilter
        if p["filter"] == "mcl":
            settings = MclSettings(particles=p["particles"], min_particles=min(500, p["particles"]), kld=p["kld"])
            built = AmclFilter(self.grid, angles, settings, rng)
        else:
            built = ReliabilityFilter(
                self.grid, angles, ReliabilitySettings(particles=p["particles"], max_range=p["max_range"]), rng
            )
        built.reset(self.initial)
        self.beams = beams
        return built

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """One filter update for the frame's odometry and scan; the PoseEstimate."""
        if not isinstance(data, Mapping) or "odometry" not in data or "ranges" not in data:
            raise ValueError(f"{self.owner} expects a mapping with 'odometry' (x, y, yaw) and 'ranges'")
        odometry = np.asarray(data["odometry"], dtype=np.float64)
        ranges = np.asarray(data["ranges"], dtype=np.float64)
        if odometry.shape != (3,) or ranges.ndim != 1 or ranges.size == 0:
            raise ValueError(f"{self.owner}: odometry must be (x, y, yaw) and ranges a non-empty vector")
        if self.filter is None or ranges.size != self.beams:
            self.filter = self._build(ranges.size)
        estimate = self.filter.update(odometry, ranges)
        message = estimate.as_message()
        message["filter"] = self.params["filter"]
        message["reliability"] = self.filter.reliability if isinstance(self.filter, ReliabilityFilter) else None
        return message

    def stop(self) -> None:
        """Forget the filter (a restart localizes again)."""
        self.filter = None
