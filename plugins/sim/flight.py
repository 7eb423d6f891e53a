"""A multirotor in the simulator: its flight controller, mixer and rotors (issue N point 2, D293).

``hardware.sim``'s ``actuator="multirotor"`` channel (bus out, size 4) takes a **velocity
set-point**, as PX4's offboard velocity control or MAVROS ``setpoint_velocity`` does: ``vx vy``
(m/s in the heading frame: x ahead, y left), ``vz`` (m/s, up) and ``yaw_rate`` (rad/s,
counter-clockwise). :class:`Multirotor` flies it, at every physics step
(:attr:`plugins.sim.world.World.before_step`, since pybullet's external forces last one step):

1. velocity error → desired acceleration (P, with the weight and the drag fed forward: the controller
   knows the model's mass and drag exactly, so it needs no integral, whose slow mode drifts a hover);
2. desired acceleration → thrust vector m·(a + g) + drag, its tilt limited to ``maxTilt``;
3. thrust vector and the yaw target (the yaw rate integrated) → the desired attitude; the collective
   thrust is its projection on the body's z axis; attitude PD on SO(3) (Lee et al. 2010) → torques;
4. mixer: collective and torques → per-rotor thrusts, the rotor positions and axes read from the
   model, the torque per newton of thrust ``yawMoment`` × ``spin``; roll and pitch keep priority
   over yaw and over the collective when a rotor would leave [0, ``maxThrust``];
5. each rotor follows its command with a first-order lag ``thrustLag``, clamped to [0, maxThrust],
   and pushes its link along its z axis; its reaction torque turns the body; linear drag slows it.

Nothing clamps the position: a thrust that cannot hold the weight makes the robot sink. On the
ground with a set-point that does not climb (vz ≤ 0) it is landed: the rotors stop and it rests on
its skids (horizontal set-points are ignored there); a climbing set-point takes off.

Set-point loss: as PX4 leaves offboard mode when its set-points stop (``COM_OF_LOSS_T``), a flying
robot that receives no set-point for ``failsafe`` simulated seconds (0: never) hovers for
:data:`FAILSAFE_HOVER` s and then descends at :data:`FAILSAFE_DESCENT` m/s until it has landed; a new
set-point ends it. So a UAV whose flight computer died does not fly on with its last command.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from .robots import Robot

Array = npt.NDArray[np.float64]
GRAVITY = 9.81
AXES = ("vx", "vy", "vz", "yaw_rate")
"""The set-point's values in order; an ``axis`` channel drives one of them (a CKM Actuator is scalar)."""
# The controller's gains (1/s, 1/s²): the velocity loops are slower than the attitude loop, which
# is kept slower than the rotors (ATTITUDE_BANDWIDTH × thrustLag), so their lag does not shake it.
VELOCITY_GAIN = np.array([2.0, 2.0, 4.0])
ATTITUDE_RATE = 12.0  # rad/s, the attitude loop's natural frequency with quick rotors
ATTITUDE_BANDWIDTH = 1.0  # the attitude loop's frequency × thrustLag stays below this
ATTITUDE_DAMPING = 0.8
YAW_RATE = 4.0  # rad/s: yaw's loop is slower, its moment (the rotors' drag) a few % of their thrust's
LIFTED = 0.2  # s: landed, but off the ground this long (not a bounce): it flies again
UP_CONTACT = 0.7  # a contact whose normal is this close to vertical is ground under the robot
FAILSAFE_HOVER = 2.0  # s of hover once the set-points stopped, before the failsafe landing
FAILSAFE_DESCENT = 0.5  # m/s, the failsafe landing's descent (at most maxClimb)


@dataclass(frozen=True)
class Airframe:
    """What the flight controller needs of the robot beyond its URDF: the ``hardware.sim`` Params."""

    rotors: tuple[str, ...]
    spin: tuple[float, ...]  # +1: the rotor's reaction turns the body counter-clockwise seen from above
    max_thrust: float  # N per rotor: the motor and propeller's own, no default
    thrust_lag: float = 0.05  # s, the rotor's time constant (hardware.sim: at most 0.2 s, slower loses the attitude)
    max_tilt: float = 0.6  # rad
    max_speed: float = 5.0  # m/s, horizontal
    max_climb: float = 3.0  # m/s, up or down
    max_yaw_rate: float = 2.0  # rad/s
    drag: float = 0.3  # N per m/s of the body's velocity
    yaw_moment: float = 0.016  # N·m of reaction torque per N of thrust
    failsafe: float = 1.0  # s without a set-point before the failsafe hover and landing (0: never)

    @classmethod
    def from_values(cls, v: dict[str, object], owner: str) -> Airframe:
        """The airframe of a channel's Params as ``hardware.sim`` reads them; ValueError naming ``owner``."""
        rotors = tuple(str(v.get("rotors") or "").split())
        if len(rotors) < 3:
            raise ValueError(f"{owner}: a multirotor needs Param 'rotors', its rotor links (3 or more)")
        try:
            spin = tuple(float(s) for s in str(v.get("spin") or "").split())
        except ValueError:
            raise ValueError(f"{owner}: Param 'spin' is {v.get('spin')!r}, not one +1 or -1 per rotor") from None
        if len(spin) != len(rotors) or any(s not in (1.0, -1.0) for s in spin):
            raise ValueError(
                f"{owner}: Param 'spin' needs one +1 or -1 per rotor ({len(rotors)}), got {v.get('spin')!r}"
            )
        if v.get("maxThrust") is None:
            raise ValueError(f"{owner}: a multirotor needs Param 'maxThrust' (N per rotor: the motor's own)")

        def number(name: str) -> float:
            return float(v[name])  # type: ignore[arg-type]

        return cls(
            rotors,
            spin,
            number("maxThrust"),
            number("thrustLag"),
            number("maxTilt"),
            number("maxSpeed"),
            number("maxClimb"),
            number("maxYawRate"),
            number("drag"),
            number("yawMoment"),
            number("failsafe"),
        )

    def setpoint(self, values: Sequence[float], owner: str) -> tuple[float, float, float, float]:
        """``values`` as a set-point (vx, vy, vz, yaw_rate); ValueError naming ``owner`` if it is not one."""
        if len(values) != 4:
            raise ValueError(f"{owner}: a multirotor takes 4 values (vx vy vz yaw_rate), got {len(values)}")
        vx, vy, vz, rate = (float(x) for x in values)
        if not all(math.isfinite(x) for x in (vx, vy, vz, rate)):
            raise ValueError(f"{owner}: set-point {list(values)} is not finite")
        limits = ((math.hypot(vx, vy), self.max_speed, "horizontal speed", "maxSpeed"),
                  (abs(vz), self.max_climb, "climb rate", "maxClimb"),
                  (abs(rate), self.max_yaw_rate, "yaw rate", "maxYawRate"))  # fmt: skip
        for value, top, what, param in limits:
            if value > top + 1e-9:
                raise ValueError(f"{owner}: set-point {list(values)}: {what} {value:.3g} is beyond {param} {top:g}")
        return vx, vy, vz, rate


def _vee(m: Array) -> Array:
    return np.array([m[2, 1], m[0, 2], m[1, 0]])


class Multirotor:
    """The rotors and flight controller of ``robot`` (see the module docstring); pushes the body at
    every physics step from construction until :meth:`detach`."""

    def __init__(self, robot: Robot, frame: Airframe, owner: str = "multirotor") -> None:
        self.robot, self.frame, self.owner = robot, frame, owner
        cid, body = robot.world.client, robot.body
        self.links = [robot.link(name) for name in frame.rotors]  # KeyError naming the robot's links
        links = range(-1, p.getNumJoints(body, physicsClientId=cid))
        self.mass = sum(p.getDynamicsInfo(body, link, physicsClientId=cid)[0] for link in links)
        base_position, base_orientation = robot.link_pose(-1)
        to_base = np.array(p.getMatrixFromQuaternion(base_orientation)).reshape(3, 3).T

        def local(world: Sequence[float]) -> Array:
            return np.asarray(to_base @ (np.asarray(world) - np.asarray(base_position)), dtype=float)

        # where the mass is, in the base's frame: the centre of mass and the inertia about it
        masses, centres, inertia = [], [], np.zeros((3, 3))
        for link in links:
            info = p.getDynamicsInfo(body, link, physicsClientId=cid)
            if link < 0:
                centre, turn = np.zeros(3), np.eye(3)
            else:
                state = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=cid)
                centre = local(state[0])
                turn = to_base @ np.array(p.getMatrixFromQuaternion(state[1])).reshape(3, 3)
            masses.append(info[0])
            centres.append(centre)
            inertia += turn @ np.diag(info[2]) @ turn.T
        self.centre = sum(m * c for m, c in zip(masses, centres, strict=True)) / self.mass
        for m, c in zip(masses, centres, strict=True):
            r = c - self.centre
            inertia += m * (r @ r * np.eye(3) - np.outer(r, r))
        self.inertia = inertia
        # each rotor's position and axis in the base's frame, from the model: where its thrust acts (its
        # link's inertial frame, which pybullet pushes in LINK_FRAME; a URDF's rotor has it at its origin)
        self.offsets, self.axes = [], []
        for link in self.links:
            state = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=cid)
            self.offsets.append(local(state[0]))
            self.axes.append(to_base @ np.array(p.getMatrixFromQuaternion(state[1])).reshape(3, 3)[:, 2])
        spin = np.asarray(frame.spin)
        columns = []
        for offset, axis, s in zip(self.offsets, self.axes, spin, strict=True):
            moment = np.cross(offset - self.centre, axis) + s * frame.yaw_moment * axis
            columns.append([axis[2], *moment])
        allocation = np.array(columns).T  # (collective, roll, pitch, yaw) per newton of each rotor
        if np.linalg.matrix_rank(allocation, tol=1e-6) < 4:
            raise ValueError(
                f"{owner}: rotors {' '.join(frame.rotors)} with spin {frame.spin} cannot control "
                "the collective thrust, roll, pitch and yaw independently"
            )
        self.mixer = np.linalg.pinv(allocation)
        self.thrust = np.zeros(len(self.links))
        """Each rotor's thrust now (N), in the order of ``rotors``."""
        self.target = np.zeros(len(self.links))
        self.setpoint = (0.0, 0.0, 0.0, 0.0)
        self.landed = False
        self.failsafe = False
        """Whether the set-points stopped and the failsafe flies the robot (module docstring)."""
        self._commanded = robot.world.time  # when the last set-point arrived (simulated s)
        self._airborne = 0  # steps since the robot last stood on something
        self._yaw: float | None = None  # the yaw held, the yaw rate integrated
        rate = min(ATTITUDE_RATE, ATTITUDE_BANDWIDTH / frame.thrust_lag) if frame.thrust_lag > 0 else ATTITUDE_RATE
        natural = np.array([rate, rate, min(rate, YAW_RATE)])
        self._k_attitude, self._k_rate = natural * natural, 2 * ATTITUDE_DAMPING * natural
        self._velocity_gain = VELOCITY_GAIN * min(1.0, rate / ATTITUDE_RATE)
        # our drag is the body's only one (pybullet's own damping is off for it)
        p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=cid)
        robot.world.before_step.append(self.push)

    def command_axis(self, axis: str, value: float, owner: str = "") -> None:
        """Fly the set-point with one of its values (:data:`AXES`) replaced by ``value``; ValueError as
        :meth:`command` (the other axes' channels keep theirs)."""
        values = list(self.setpoint)
        values[AXES.index(axis)] = value
        self.command(values, owner)

    def command(self, values: Sequence[float], owner: str = "") -> None:
        """Fly the set-point (vx, vy, vz, yaw_rate) from now on; ValueError naming ``owner`` (default:
        the first channel's) if it is not one."""
        self.setpoint = self.frame.setpoint(values, owner or self.owner)
        self._commanded = self.robot.world.time
        self.failsafe = False

    def detach(self) -> None:
        """Stop pushing the body (the rotors are off from the next step)."""
        if self.push in self.robot.world.before_step:
            self.robot.world.before_step.remove(self.push)

    def _failsafe_setpoint(self) -> tuple[float, float, float, float]:
        """The set-point to fly: the last one, or once set-points stopped the failsafe's hover, then descent."""
        silent = self.robot.world.time - self._commanded
        if self.frame.failsafe <= 0.0 or silent <= self.frame.failsafe:
            return self.setpoint
        self.failsafe = True
        if silent <= self.frame.failsafe + FAILSAFE_HOVER:
            return (0.0, 0.0, 0.0, 0.0)
        return (0.0, 0.0, -min(FAILSAFE_DESCENT, self.frame.max_climb), 0.0)

    def _on_ground(self) -> bool:
        contacts = p.getContactPoints(bodyA=self.robot.body, physicsClientId=self.robot.world.client)
        return any(c[2] != self.robot.body and c[7][2] > UP_CONTACT for c in contacts)

    def push(self) -> None:
        """One physics step of the flight controller and the rotors (called before ``stepSimulation``)."""
        cid, body, frame = self.robot.world.client, self.robot.body, self.frame
        dt = self.robot.world.time_step
        _, orientation = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        linear, angular = p.getBaseVelocity(body, physicsClientId=cid)
        rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        velocity = np.asarray(linear)
        yaw = math.atan2(rotation[1, 0], rotation[0, 0])
        vx, vy, vz, yaw_rate = self._failsafe_setpoint()
        on_ground = self._on_ground()
        self._airborne = 0 if on_ground else self._airborne + 1
        if vz > 0.0 or self._airborne * dt > LIFTED:  # taking off, or lifted (pushed off a ledge): fly
            self.landed = False
        elif not self.landed and on_ground:
            self.landed = True
        if self.landed:  # motors idle, the controller's memory cleared for the next take-off
            self.target[:] = 0.0
            self._yaw = yaw
        else:
            self.target = self._control(rotation, velocity, np.asarray(angular), yaw, (vx, vy, vz, yaw_rate), dt)
        lag = 1.0 - math.exp(-dt / frame.thrust_lag) if frame.thrust_lag > 0 else 1.0
        self.thrust = np.clip(self.thrust + lag * (self.target - self.thrust), 0.0, frame.max_thrust)
        reaction = np.zeros(3)
        for link, axis, thrust, s in zip(self.links, self.axes, self.thrust, frame.spin, strict=True):
            # in the link's own frame: a world position would be one step stale inside pybullet, a moment
            # arm of v·dt that pitches a flying robot up
            p.applyExternalForce(
                body, link, [0.0, 0.0, float(thrust)], [0.0, 0.0, 0.0], p.LINK_FRAME, physicsClientId=cid
            )
            reaction += s * frame.yaw_moment * thrust * (rotation @ axis)
        p.applyExternalTorque(body, -1, reaction.tolist(), p.WORLD_FRAME, physicsClientId=cid)
        if frame.drag > 0.0:
            drag = rotation.T @ (-frame.drag * velocity)  # at the base's centre of mass, in its frame (as above)
            p.applyExternalForce(body, -1, drag.tolist(), [0.0, 0.0, 0.0], p.LINK_FRAME, physicsClientId=cid)

    def _control(
        self,
        rotation: Array,
        velocity: Array,
        angular: Array,
        yaw: float,
        setpoint: tuple[float, float, float, float],
        dt: float,
    ) -> Array:
        """The rotors' thrust commands for one step of flight."""
        frame = self.frame
        vx, vy, vz, yaw_rate = setpoint
        c, s = math.cos(yaw), math.sin(yaw)
        wanted = np.array([c * vx - s * vy, s * vx + c * vy, vz])  # the heading frame → the world
        error = wanted - velocity
        accel = self._velocity_gain * error
        force = self.mass * (accel + np.array([0.0, 0.0, GRAVITY])) + frame.drag * velocity
        force[2] = max(force[2], 0.1 * self.mass * GRAVITY)  # never ask to be pulled down: keep it upright
        lateral, reach = math.hypot(force[0], force[1]), force[2] * math.tan(frame.max_tilt)
        if lateral > reach:
            force[:2] *= reach / lateral
        up = force / np.linalg.norm(force)
        self._yaw = (yaw if self._yaw is None else self._yaw) + yaw_rate * dt
        heading = np.array([math.cos(self._yaw), math.sin(self._yaw), 0.0])
        side = np.cross(up, heading)
        side /= np.linalg.norm(side)
        desired = np.column_stack([np.cross(side, up), side, up])
        collective = max(0.0, float(force @ rotation[:, 2]))
        attitude_error = 0.5 * _vee(desired.T @ rotation - rotation.T @ desired)
        rate_error = rotation.T @ angular - np.array([0.0, 0.0, yaw_rate])
        body_rate = rotation.T @ angular
        torque = self.inertia @ (-self._k_attitude * attitude_error - self._k_rate * rate_error)
        torque += np.cross(body_rate, self.inertia @ body_rate)
        return self._mix(collective, torque)

    def _mix(self, collective: float, torque: Array) -> Array:
        """Per-rotor thrusts giving ``collective`` and ``torque``; when a rotor would leave [0, maxThrust],
        yaw yields first, then the collective, so roll and pitch keep the robot upright."""
        top = self.frame.max_thrust
        share: Array = self.mixer[:, 0]  # each rotor's part of one newton of collective thrust
        tilting = self.mixer[:, 1:3] @ torque[:2]
        turning = self.mixer[:, 3] * torque[2]
        if share.min() <= 1e-9:  # a rotor that does not lift: no collective range to search
            return np.asarray(np.clip(collective * share + tilting + turning, 0.0, top), dtype=float)
        low = max(-tilting / share)  # the collective range that keeps every rotor in bounds
        high = min((top - tilting) / share)
        if low > high:  # even roll and pitch alone do not fit
            return np.asarray(np.clip(collective * share + tilting, 0.0, top), dtype=float)
        level = min(max(collective, low), high) * share + tilting
        # as much of the yaw as fits beside them (a rotor's yaw moment is a few % of its thrust)
        room = np.where(turning > 0, top - level, level)
        part = np.divide(room, np.abs(turning), out=np.ones_like(room), where=np.abs(turning) > 1e-12)
        return np.asarray(level + min(1.0, max(0.0, float(part.min()))) * turning, dtype=float)
