"""``controller.diff-drive-odometry``: dead reckoning of a differential base with its covariance (§7.1, Table 7.1).

Inputs: the two wheel rim speeds in m/s (``role="measure"`` twice, left then right, or roles
``left`` and ``right``) — the encoder counts after the sensors' adaptation (ticks/s × 2πr/ticks).
Each period the wheels travel Δl = v_l·dt, Δr = v_r·dt; with b = ``wheelBase``,
Δs = (Δr + Δl)/2 and Δθ = (Δr − Δl)/b, the pose is integrated at the arc's mid-angle

    x += Δs·cos(θ + Δθ/2),   y += Δs·sin(θ + Δθ/2),   θ += Δθ.

Error model (Siegwart & Nourbakhsh, eq. 5.9): each wheel's travel has variance ``wheelError``·|Δ|
(m² per metre travelled), independent between wheels, and the pose covariance is propagated as
Σ ← F_p Σ F_pᵀ + F_Δ Σ_Δ F_Δᵀ. The output is an ``Odometry`` message: ``stamp``, ``pose``
{x, y, yaw}, ``twist`` {linear, angular} from the measured wheel speeds and ``dispersion`` =
√(σ_x² + σ_y²), the radius of the position uncertainty: the Mobile Base Displacement service's
"Odometry Dispersion" (Table 7.1; D92). It only grows while the base moves.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.kernel.interfaces import ParamError, read_params
from runtime.verification.manifest import MAPPING, NUMBER, REQUIRED, P, Params, Ports

from .common import check_state
from .multi import MultiOutputController, Row, input_roles, role_values


class DiffDriveOdometry(MultiOutputController):
    """Pose, twist and odometry dispersion of a differential base from its wheel speeds."""

    kind = "diff-drive-odometry"
    PARAMS = Params(
        P("wheelBase", REQUIRED, "Distance between the wheels' contact points.", type=float, unit="m", above=0.0),
        P("wheelError", 1e-4, "Variance of a wheel's travel per metre travelled (slip, radius error).",
          unit="m", min=0.0),
        P("x", 0.0, "Initial x of the pose.", unit="m"),
        P("y", 0.0, "Initial y of the pose.", unit="m"),
        P("yaw", 0.0, "Initial heading.", unit="rad"),
    )
    PORTS = Ports(inputs={"*": NUMBER}, outputs={"*": MAPPING})  # stamp, pose, twist, dispersion

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record, outputs=1)
        values = read_params(record.params, self.PARAMS, owner=self.owner)
        roles = input_roles(record)
        if sorted(roles) == ["left", "right"]:
            self.roles = ("left", "right")
        elif roles == ["measure", "measure"]:
            self.roles = ("measure", "measure")
        else:
            raise ParamError(
                f"{self.owner} reads the left and right wheel speeds: two inputs with role 'measure' "
                f"(left first) or roles 'left' and 'right', not {', '.join(roles) or 'none'}"
            )
        self.base: float = values["wheelBase"]
        self.error: float = values["wheelError"]
        self.pose = np.array([values["x"], values["y"], values["yaw"]], dtype=float)
        self.covariance = np.zeros((3, 3))
        self.twist = (0.0, 0.0)

    def wheels(self, inputs: Mapping[str, Any]) -> tuple[float, float]:
        """(left, right) wheel speeds from the inputs."""
        if self.roles == ("left", "right"):
            return float(inputs["left"]), float(inputs["right"])
        speeds = role_values(inputs, "measure")
        if len(speeds) != 2:
            raise KeyError(f"{self.owner}: expected inputs 'measure[0]' and 'measure[1]', got {sorted(inputs)}")
        return float(speeds[0]), float(speeds[1])

    def advance(self, left: float, right: float) -> None:
        """Integrate wheel travels ``left`` and ``right`` (m) into the pose and its covariance."""
        b, theta = self.base, self.pose[2]
        ds, dtheta = (right + left) / 2.0, (right - left) / b
        mid = theta + dtheta / 2.0
        c, s = math.cos(mid), math.sin(mid)
        f_pose = np.array([[1.0, 0.0, -ds * s], [0.0, 1.0, ds * c], [0.0, 0.0, 1.0]])
        f_wheels = np.array(
            [
                [c / 2 + ds * s / (2 * b), c / 2 - ds * s / (2 * b)],
                [s / 2 - ds * c / (2 * b), s / 2 + ds * c / (2 * b)],
                [-1.0 / b, 1.0 / b],
            ]
        )  # columns: ∂/∂Δl, ∂/∂Δr
        wheel_cov = np.diag([self.error * abs(left), self.error * abs(right)])
        self.covariance = f_pose @ self.covariance @ f_pose.T + f_wheels @ wheel_cov @ f_wheels.T
        self.pose = self.pose + np.array([ds * c, ds * s, dtheta])
        self.pose[2] = math.atan2(math.sin(self.pose[2]), math.cos(self.pose[2]))

    @property
    def dispersion(self) -> float:
        """√(σ_x² + σ_y²): the radius of the position uncertainty, in metres."""
        return math.sqrt(max(0.0, float(self.covariance[0, 0] + self.covariance[1, 1])))

    def message(self) -> dict[str, Any]:
        """The current estimate as an ``Odometry`` message."""
        x, y, yaw = (float(v) for v in self.pose)
        return {
            "stamp": time.time(),
            "pose": {"x": x, "y": y, "yaw": yaw},
            "twist": {"linear": self.twist[0], "angular": self.twist[1]},
            "dispersion": self.dispersion,
        }

    def step_outputs(self, inputs: Mapping[str, Any], dt: float) -> Row:
        """Integrate the wheel travel of this period and return the ``Odometry`` message."""
        dt = dt if dt > 0.0 else self.record.period
        left, right = self.wheels(inputs)
        self.advance(left * dt, right * dt)
        self.twist = ((left + right) / 2.0, (right - left) / self.base)
        return (self.message(),)

    def state(self) -> dict[str, Any]:
        """Pose and covariance (code delegation, §3.1.2.6)."""
        return {
            "kind": self.kind,
            "pose": [float(v) for v in self.pose],
            "covariance": [float(v) for v in self.covariance.ravel()],
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a diff-drive-odometry controller.

        Raises:
            ValueError: the state is not one.
        """
        check_state(state, self.kind, ("pose", "covariance"))
        self.pose = np.array([float(v) for v in state["pose"]], dtype=float)
        self.covariance = np.array([float(v) for v in state["covariance"]], dtype=float).reshape(3, 3)
