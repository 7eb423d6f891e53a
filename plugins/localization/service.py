"""``plugin.localization``: the Navigation service's localization as an SPT processing plugin (§6.2.1, Table 7.1).

Configured by ``<Plugin kind="localization">`` (ckm.xsd). Each frame brings the odometry reading and
a laser scan of any robot; the plugin runs one step of the selected filter — ``filter=reliability``
(Algorithm 3) or ``filter=mcl`` (the AMCL-like baseline) — and returns the PoseEstimate: the pose,
its 3×3 covariance and the localization dispersion, the quality measure of the use case's AMCL
service (``localization_dispersion``).

A frame is a mapping, one of (or a mix of the two halves of):

- the standard inputs ``scan`` (a ``sensor_msgs/LaserScan`` mapping: ``angle_min``,
  ``angle_increment``, ``range_min``, ``range_max``, ``ranges``; the beam geometry is the scan's
  own) and ``odom`` (a ``nav_msgs/Odometry``-like mapping whose ``pose`` is ``{x, y, yaw}``);
- the raw form ``{"odometry": (x, y, yaw), "ranges": [...]}``, whose geometry the Params ``fov``
  and ``max_range`` give (no default: they describe the robot's laser, D283).

The laser sits ``laserPose`` off the base's centre (required): every beam is re-expressed from the
centre (plugins/localization/beams.py), so the estimate is the base's pose, whatever the mount.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

import ckmconf
from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, NUMBERS, REQUIRED, P, Params, Ports

from .beams import LaserBeams, Pose, raw_beams, reach, robot_beams, scan_beams
from .likelihood import FieldModel
from .mcl import AmclFilter, MclSettings
from .odometry import wrap
from .raster import GridMap
from .reliability_filter import ReliabilityFilter, ReliabilitySettings

Array = npt.NDArray[np.float64]


def pose_param(text: str, name: str, owner: str) -> Pose:
    """A Param ``"x y yaw"`` as three finite numbers; ParamError naming ``owner`` and the Param otherwise."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ParamError(f"{owner}: parameter {name!r} = {text!r} is not 'x y yaw' (three finite numbers: m, m, rad)")
    return values[0], values[1], values[2]


def _number(fields: Mapping[str, Any], key: str, owner: str) -> float:
    value = fields.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}: input 'odom' field 'pose' field {key!r} must be a finite number, got {value!r}")
    return float(value)


def odom_pose(message: Any, owner: str) -> Array:
    """The ``pose`` {x, y, yaw} of an Odometry-like mapping (as plugins/navigation reads it)."""
    pose = message.get("pose") if isinstance(message, Mapping) else None
    if not isinstance(pose, Mapping):
        raise ValueError(f"{owner}: input 'odom' must be an Odometry mapping with a 'pose' {{x, y, yaw}}")
    return np.array([_number(pose, "x", owner), _number(pose, "y", owner), float(wrap(_number(pose, "yaw", owner)))])


class Localization(ProcessingPlugin):
    """``plugin.localization`` (``<Plugin kind="localization">``, §6.2.1): one filter step per frame.

    Inputs: ``scan`` (LaserScan) and ``odom`` (Odometry), or the raw ``odometry`` (x, y, yaw) and
    ``ranges`` (with the Params ``fov`` and ``max_range``); see the module docstring. Returns
    ``{"x", "y", "yaw", "covariance" (9 floats, row-major), "dispersion", "filter", "reliability"}``
    for the robot's centre; ``reliability`` is R of eq. 6.21 for Algorithm 3 and None for MCL.
    """

    # "*": one service Input carrying a whole frame mapping
    PORTS = Ports(
        inputs={"odometry": NUMBERS, "ranges": NUMBERS, "scan": MAPPING, "odom": MAPPING, "*": MAPPING},
        outputs={"*": MAPPING},
    )
    PROVIDES = "localization"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {
        "pose": ("x", "y", "yaw", "covariance", "dispersion", "filter", "reliability")
    }
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P(
            "filter",
            "reliability",
            "Algorithm 3 ('reliability') or the AMCL-like baseline ('mcl').",
            choices=("reliability", "mcl"),
        ),
        P("particles", 2500, "Number of particles (MCL: the maximum with KLD sampling).", min=10),
        P(
            "environment",
            REQUIRED,
            "XML file holding the system's <Environment> (the map), relative to the configuration file.",
            type=str,
            file=ENVIRONMENT_FILE,
        ),
        P(
            "laserPose",
            REQUIRED,
            "The laser's mount 'x y yaw' in the robot frame (m, m, rad): the URDF's laser "
            "joint. Beams are re-expressed from the robot's centre, so the estimate is the base's pose.",
            type=str,
            numbers=(3,), form="'x y yaw'",
        ),
        P("laserHeight", REQUIRED, "Height of the scan plane above the floor: the map's objects it cuts (as "
          "amcl-navigation's).", type=float, unit="m", above=0.0),
        P("beams", 60, "Beams of each scan used by the filter, evenly spread (AMCL's laser_max_beams).", min=3),
        P("resolution", 0.05, "Grid cell size of the map.", unit="m", above=0.0),
        P(
            "fov",
            None,
            "Raw 'ranges' frames only (required for them; a 'scan' carries its own geometry): the "
            "laser's field of view, the ranges spread evenly over it centred on the laser's heading (2π: a full "
            "turn from -π).",
            type=float,
            unit="rad",
            above=0.0,
            max=2 * math.pi,
        ),
        P(
            "max_range",
            None,
            "Raw 'ranges' frames only (required for them): the laser's longest range, a reading "
            "at or beyond it is no return.",
            type=float,
            unit="m",
            above=0.0,
        ),
        P("initial_pose", "", "'x y yaw' of the robot to start around, empty for global localization.",
          numbers=(3,), form="'x y yaw'"),
        P("kld", False, "MCL only: KLD sampling of the particle count."),
        P("seed", 0, "Random seed of the filter.", min=0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.laser = pose_param(self.params["laserPose"], "laserPose", self.owner)
        text = self.params["initial_pose"]
        self.initial = np.array(pose_param(text, "initial_pose", self.owner)) if text.strip() else None
        self.grid: GridMap | None = None
        self.filter: AmclFilter | ReliabilityFilter | None = None
        self.reach = 0.0
        """The range the filter's models take (m): the scan's longest valid beam seen from the centre."""

    def setup(self) -> None:
        """Load the environment and rasterise it."""
        path = config_dir(self.record) / self.params["environment"]
        env = ckmconf.load(path).environment
        if env is None:
            raise ParamError(f"{self.owner}: {path} holds no <Environment>")
        self.grid = GridMap.from_environment(env, self.params["resolution"], scan_height=self.params["laserHeight"])

    def _filter(self, longest: float) -> AmclFilter | ReliabilityFilter:
        """The filter, built at the first frame; its models follow the scan's range if that changes."""
        if self.filter is not None and longest == self.reach:
            return self.filter
        p = self.params
        self.reach = longest
        if self.filter is None:
            if self.grid is None:
                self.setup()
            assert self.grid is not None
            rng = np.random.default_rng(p["seed"])
            built: AmclFilter | ReliabilityFilter
            if p["filter"] == "mcl":
                settings = MclSettings(
                    particles=p["particles"],
                    min_particles=min(500, p["particles"]),
                    kld=p["kld"],
                    field=FieldModel(max_range=longest),
                )
                built = AmclFilter(self.grid, np.zeros(0), settings, rng)
            else:
                built = ReliabilityFilter(
                    self.grid, np.zeros(0), ReliabilitySettings(particles=p["particles"], max_range=longest), rng
                )
            built.reset(self.initial)
            self.filter = built
        elif isinstance(self.filter, AmclFilter):
            self.filter.settings = replace(
                self.filter.settings, field=replace(self.filter.settings.field, max_range=longest)
            )
        else:
            self.filter.settings = replace(self.filter.settings, max_range=longest)
        return self.filter

    def _either(self, data: Mapping[str, Any], standard: str, raw: str) -> tuple[Any, Any]:
        """The frame's ``standard`` and ``raw`` inputs, at most one of them given."""
        one, other = data.get(standard), data.get(raw)
        if one is not None and other is not None:
            raise ValueError(f"{self.owner}: the frame has both {standard!r} and {raw!r}: give one")
        return one, other

    def _odometry(self, data: Mapping[str, Any]) -> Array:
        odom, raw = self._either(data, "odom", "odometry")
        if odom is not None:
            return odom_pose(odom, self.owner)
        if raw is None:
            raise ValueError(
                f"{self.owner} expects the odometry: input 'odom' (an Odometry) or 'odometry' "
                f"(x, y, yaw); the frame has {sorted(map(str, data))}"
            )
        try:
            odometry = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            odometry = np.zeros(0)
        if odometry.shape != (3,) or not np.isfinite(odometry).all():
            raise ValueError(f"{self.owner}: odometry must be (x, y, yaw), three finite numbers")
        return odometry

    def _sweep(self, data: Mapping[str, Any]) -> LaserBeams:
        scan, raw = self._either(data, "scan", "ranges")
        if scan is not None:
            if not isinstance(scan, Mapping):
                raise ValueError(f"{self.owner}: input 'scan' must be a LaserScan mapping, got {type(scan).__name__}")
            return scan_beams(scan, self.owner)
        if raw is None:
            raise ValueError(
                f"{self.owner} expects a laser scan: input 'scan' (a LaserScan) or 'ranges'; the frame "
                f"has {sorted(map(str, data))}"
            )
        fov, max_range = self.params["fov"], self.params["max_range"]
        if fov is None or max_range is None:
            missing = " and ".join(repr(n) for n, v in (("fov", fov), ("max_range", max_range)) if v is None)
            raise ParamError(
                f"{self.owner}: a raw 'ranges' frame needs the parameters 'fov' and 'max_range' (the "
                f"laser's field of view and range), {missing} not given; or send a LaserScan as input "
                f"'scan', which carries its own geometry"
            )
        try:
            ranges = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            ranges = np.zeros(0)
        if ranges.ndim != 1 or ranges.size == 0:
            raise ValueError(f"{self.owner}: ranges must be a non-empty vector of numbers")
        return raw_beams(ranges, fov, max_range)

    def process(self, data: Any, context: Context) -> dict[str, Any] | None:
        """One filter update for the frame's odometry and scan; the PoseEstimate of the robot's centre.
        None (nothing published) while the frame's odometry or scan has not arrived yet."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects a mapping: 'scan' and 'odom', or 'odometry' and 'ranges'")
        names = set(map(str, data))
        expected = names & {"odom", "odometry"} and names & {"scan", "ranges"}
        if expected and any(all(data.get(n) is None for n in pair if n in names)
                            for pair in (("odom", "odometry"), ("scan", "ranges"))):
            return None
        odometry = self._odometry(data)
        sweep = self._sweep(data)
        ranges, bearings = robot_beams(sweep, self.laser, self.params["beams"])
        active = self._filter(reach(sweep.range_max, self.laser))
        estimate = active.update(odometry, ranges, bearings)
        message = estimate.as_message()
        message["filter"] = self.params["filter"]
        message["reliability"] = active.reliability if isinstance(active, ReliabilityFilter) else None
        return message

    def stop(self) -> None:
        """Forget the filter (a restart localizes again)."""
        self.filter = None
