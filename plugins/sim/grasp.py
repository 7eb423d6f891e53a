"""The gripper and its grasp (decision D87): the fingers close under a force limit, and a fixed
constraint between the wrist and the object is created only while both fingers touch the object;
the constraint's force limit lets a too-heavy or snagged object slip out, and opening releases it.

:class:`ChannelGrasp` gives a ``sim`` gripper channel (Param ``grasp``) that grasp: the channel
drives the fingers, the grasp follows its commands and the world's steps (D187).

Nothing here is one robot's (D296): the fingers, the link that holds and the forces are the
model's or the caller's. Any movable body both fingers touch is caught, whatever its size (the jaw's
opening, from the finger joints' limits, is what bounds it); the closing force is the finger joints'
effort limit, and the hold force, unless given, the friction grip those fingers give,
``2 × GRIP_FRICTION × effort``. A held object that moves ``SLIP_DISTANCE`` from where it was
caught — too heavy for the hold force — has slipped out: the grasp lets it go."""

from __future__ import annotations

import logging
import math

import pybullet as p

from .robots import Robot

LOG = logging.getLogger("ckm.sim.grasp")

GRIP_FRICTION = 0.75
"""Friction coefficient of a finger pad on what it holds (rubber on cardboard or plastic, 0.6-0.9):
two fingers pressing with force F hold 2·μ·F before the object slips."""
SLIP_DISTANCE = 0.02
"""m a held object may move from where it was caught (relative to the holding link) before it has
slipped out of the fingers."""


def hold_force_of(robot: Robot, fingers: tuple[int, int]) -> float:
    """The friction grip of two fingers pressing at their joints' effort limit (N): 2·μ·F."""
    return 2.0 * GRIP_FRICTION * min(robot.max_effort(f) for f in fingers)


class Gripper:
    """Two fingers (``left`` and its mirror ``right``, each joint its finger's travel from closed at
    its lower limit) on the ``wrist`` link that holds what they grasp: any parallel jaw so made (the
    Turtlebot's, the station arm's D267, the carrier's clamp D296) by its joint and link names.
    ``force`` (N) closes the fingers (None: their joint's effort limit); ``hold_force`` (N) is the
    constraint's limit (None: :func:`hold_force_of` the fingers)."""

    def __init__(
        self, robot: Robot, *, left: str, right: str, wrist: str, force: float | None = None,
        hold_force: float | None = None,
    ) -> None:
        self.robot = robot
        self.fingers = (robot.joint(left), robot.joint(right))
        self.finger_links = self.fingers  # a joint's child link has the joint's index
        self.wrist = robot.link(wrist)
        self.force = force if force is not None else robot.max_effort(self.fingers[0])
        self.hold_force = hold_force if hold_force is not None else hold_force_of(robot, self.fingers)
        self.open_limit = float(p.getJointInfo(robot.body, self.fingers[0], physicsClientId=robot.world.client)[9])
        self.held: int | None = None
        self._constraint: int | None = None
        self._caught_at: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the held body in the wrist frame

    def set_opening(self, opening: float) -> None:
        """Drive each finger to ``opening`` (m from its closed stop)."""
        for joint in self.fingers:
            self.robot.command(joint, "position", opening, self.force)
        if opening > 0.0 and self._constraint is not None:
            self.release()

    def open(self) -> None:
        """Open fully, to the finger joint's upper limit (releases a held object)."""
        self.set_opening(self.open_limit)

    def close(self) -> None:
        """Close under the force limit; call :meth:`update` while closing to catch the object."""
        for joint in self.fingers:
            self.robot.command(joint, "position", 0.0, self.force)

    def touching(self) -> int | None:
        """The movable body both fingers touch now, if any (a table or a wall is never grasped)."""
        cid = self.robot.world.client
        touched = [
            {c[2] for c in p.getContactPoints(bodyA=self.robot.body, linkIndexA=link, physicsClientId=cid)}
            - {self.robot.body, self.robot.world.floor}
            for link in self.finger_links
        ]
        common = {b for b in touched[0] & touched[1] if p.getDynamicsInfo(b, -1, physicsClientId=cid)[0] > 0.0}
        return min(common) if common else None

    def update(self) -> int | None:
        """Create the grasp constraint when both fingers touch one object; returns the held body."""
        if self._constraint is not None:
            return self.held
        body = self.touching()
        if body is None:
            return None
        cid = self.robot.world.client
        wrist_pos, wrist_orn = self._wrist_frame()
        obj_pos, obj_orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        inv_pos, inv_orn = p.invertTransform(wrist_pos, wrist_orn)
        rel_pos, rel_orn = p.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)
        self._constraint = p.createConstraint(
            self.robot.body, self.wrist, body, -1, p.JOINT_FIXED, [0, 0, 0], rel_pos, [0, 0, 0],
            parentFrameOrientation=rel_orn, physicsClientId=cid,
        )
        p.changeConstraint(self._constraint, maxForce=self.hold_force, physicsClientId=cid)
        self.held = body
        self._caught_at = (float(rel_pos[0]), float(rel_pos[1]), float(rel_pos[2]))
        return body

    def _wrist_frame(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The holding link's centre-of-mass frame: a constraint's parent frame is given in it, not
        in the link's own frame (they differ by the link's inertial origin, D296)."""
        cid = self.robot.world.client
        if self.wrist < 0:
            position, orientation = p.getBasePositionAndOrientation(self.robot.body, physicsClientId=cid)
            return tuple(position), tuple(orientation)
        state = p.getLinkState(self.robot.body, self.wrist, computeForwardKinematics=True, physicsClientId=cid)
        return tuple(state[0]), tuple(state[1])

    def slip(self) -> float:
        """How far (m) the held body has moved from where it was caught, in the wrist's frame (0: none held)."""
        if self.held is None:
            return 0.0
        wrist_pos, wrist_orn = self._wrist_frame()
        obj_pos, _ = p.getBasePositionAndOrientation(self.held, physicsClientId=self.robot.world.client)
        inv_pos, inv_orn = p.invertTransform(wrist_pos, wrist_orn)
        here, _ = p.multiplyTransforms(inv_pos, inv_orn, obj_pos, (0.0, 0.0, 0.0, 1.0))
        return math.dist(here, self._caught_at)

    def release(self) -> None:
        """Remove the grasp constraint."""
        if self._constraint is not None and self.attached():
            p.removeConstraint(self._constraint, physicsClientId=self.robot.world.client)
        self._constraint, self.held = None, None

    def attached(self) -> bool:
        """Whether the grasp constraint still exists (a world disturbance may have removed it)."""
        cid = self.robot.world.client
        count = p.getNumConstraints(physicsClientId=cid)
        return self._constraint in {p.getConstraintUniqueId(i, physicsClientId=cid) for i in range(count)}


class ChannelGrasp:
    """The grasp of a ``sim`` gripper channel (D87, D187): its ``joint`` and ``mirror`` fingers
    close towards their lower limit. A command below where the fingers stand starts closing; an
    object both fingers touch while closing is caught (checked after each advance of the world).
    It is let go when the fingers have really opened — by ``RELEASE_GAP`` beyond where they
    stood on it, or to their open stop when they caught it nearer to it than that — not on a
    command: a servo's quantised command to hold its position can round
    a step up, and the object must not fall for that. A ``hold_force`` of 0 or less is the
    fingers' own (:func:`hold_force_of`, D296); an object that slips out (too heavy for it) is let go."""

    RELEASE_GAP = 0.003
    """m the fingers must open beyond their opening on the object to let it go."""

    def __init__(self, robot: Robot, joint: str, mirror: str, link: str, hold_force: float) -> None:
        self.gripper = Gripper(robot, left=joint, right=mirror, wrist=link,
                               hold_force=hold_force if hold_force > 0.0 else None)
        self.closing = False
        self.slipped = False  # an object slipped out: nothing is caught until the fingers open
        self.opening_held = 0.0
        self.target = 0.0
        robot.world.hooks.append(self._after_advance)

    def _opening(self) -> float:
        return float(self.gripper.robot.joint_state(self.gripper.fingers[0])[0])

    SQUEEZE = 0.001
    """m the fingers press into a caught object (a servo stalled on it at its torque limit)."""

    def command(self, target: float) -> None:
        """The channel drove the fingers to ``target`` (joint units)."""
        position = self._opening()
        if target < position - self.RELEASE_GAP:  # closing (not a servo step's rounding)
            self.closing = not self.slipped  # what slipped out is not caught again before they open
        elif target > position + self.RELEASE_GAP:  # opening: nothing is caught on the way
            self.closing = self.slipped = False
        self.target = target
        if self.gripper.held is not None:
            self._stall()

    def _stall(self) -> None:
        """Fingers on a caught object stop there, pressing lightly: squeezing a round object on
        and on would wedge it out between them along the grasp constraint (D187)."""
        at = max(self.target, self.opening_held - self.SQUEEZE)
        for finger in self.gripper.fingers:
            self.gripper.robot.command(finger, "position", at)

    def _after_advance(self, _world: object) -> None:
        if self.gripper.held is not None:
            if not self.gripper.attached():  # taken out of the fingers (a disturbance, issue K.3d)
                LOG.info("t=%.2f: body %s was taken out of the fingers", self.gripper.robot.world.time,
                         self.gripper.held)
                self.gripper.release()
                for finger in self.gripper.fingers:  # the stalled servos close on nothing, to their target
                    self.gripper.robot.command(finger, "position", self.target)
            elif self.gripper.slip() > SLIP_DISTANCE:  # heavier than the hold force holds (D296)
                LOG.info("t=%.2f: body %s slipped out of the fingers (%.3f m)", self.gripper.robot.world.time,
                         self.gripper.held, self.gripper.slip())
                self.gripper.release()
                self.closing, self.slipped = False, True
                for finger in self.gripper.fingers:
                    self.gripper.robot.command(finger, "position", self.target)
            elif self._opening() > self.opening_held + self.RELEASE_GAP or self._opened_to_the_stop():
                LOG.info("t=%.2f: let go of body %s (fingers opened to %.4f m)", self.gripper.robot.world.time,
                         self.gripper.held, self._opening())
                self.gripper.release()
                self.closing = False
        elif self.closing and self.gripper.update() is not None:
            self.opening_held = self._opening()
            self._stall()
            LOG.info("t=%.2f: caught body %s (fingers at %.4f m)", self.gripper.robot.world.time, self.gripper.held,
                     self.opening_held)

    def _opened_to_the_stop(self) -> bool:
        """Opened as far as the fingers go, beyond where they caught the object: an object caught less than
        ``RELEASE_GAP`` short of the open stop (as wide as the jaw) is let go there, or it would be held for good."""
        limit = self.gripper.open_limit
        position = self._opening()
        return self.target >= limit - 1e-9 and position >= limit - self.RELEASE_GAP and position > self.opening_held

    @property
    def held(self) -> int | None:
        """The body held now, if any."""
        return self.gripper.held
