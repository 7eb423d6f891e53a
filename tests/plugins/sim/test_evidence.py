"""The world's trace (plugins/sim/evidence.py ``Trace``): every robot's planar pose and its pose in 3D,
so where a lifted, tipped or flying body went is in ``sim-final.json`` (issue N point 2)."""

from __future__ import annotations

import math

import pybullet as p
import pytest

from plugins.hardware.simulation import ManualClock
from plugins.sim.devices import SimWorld
from plugins.sim.evidence import Trace


def test_the_trace_holds_each_robot_s_3d_pose_beside_its_planar_one() -> None:
    sim = SimWorld(ManualClock(), None, 0, "", "")
    try:
        rover = sim.robot("rover", "", "1.0 2.0 0.5")
        trace = Trace(sim, every=0.1)
        sim.world.step(30)
        (sample,) = [s for s in trace.samples if s["steps"] == 30]
        x, y, z, roll, pitch, yaw = sample["bodies"]["rover"]
        assert (x, y, yaw) == pytest.approx(sample["robots"]["rover"], abs=1e-3)
        assert abs(roll) < 0.02 and abs(pitch) < 0.02 and 0.0 <= z < 0.2  # standing on its wheels
        # lifted 1.5 m and tipped on its side: the planar pose cannot say it, the 3D pose does
        tipped = p.getQuaternionFromEuler([math.pi / 2, 0.0, 0.5])
        p.resetBasePositionAndOrientation(rover.body, [1.0, 2.0, 1.5], tipped, physicsClientId=sim.world.client)
        sim.world.step(24)
        x, y, z, roll, _, _ = trace.samples[-1]["bodies"]["rover"]
        assert z > 1.3 and abs(roll) > 1.3
    finally:
        sim.world.close()
