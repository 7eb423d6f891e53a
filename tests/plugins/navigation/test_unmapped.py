"""Beams that hit something the map lacks are ignored by the localization (D235): a crate the map does
not hold, 0.5 m ahead, fills a fifth of the scan; scored as unexplained it scattered Algorithm 3's
particles and the estimate jumped metres away (lab blocked-path seeds 204 and 205)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import shapely

from runtime.resources.spt import Context

from .loop import room
from .test_amcl import grid, navigation, odometry, scan

CRATE = shapely.box(1.75, 0.35, 2.25, 0.85)
"""0.5 m square, its near face 0.75 m ahead of the robot at (1.0, 0.6) facing east."""


def _drive(directory: Path, unmapped: float, seed: int) -> tuple[float, list[int]]:
    """25 frames creeping east toward the crate (exact odometry): the worst position error, the ignored beams."""
    file = room(directory)
    world = grid(file, CRATE)
    nav = navigation(file, unmapped=unmapped, initialPose="1.0 0.6 0", initialSpread="0.05 0.05", seed=seed)
    worst, ignored = 0.0, []
    for k in range(25):
        truth = (1.0 + 0.02 * k, 0.6, 0.0)
        out = nav.process({"scan": scan(world, truth), "odom": odometry(truth)}, Context(k, 0.8 * k))
        pose = out["pose"]["pose"]
        worst = max(worst, math.hypot(pose["x"] - truth[0], pose["y"] - truth[1]))
        assert nav.localizer is not None
        ignored.append(nav.localizer.ignored)
    return worst, ignored


@pytest.mark.parametrize("seed", [0, 1])
def test_the_estimate_stays_put_beside_a_crate_the_map_lacks(tmp_path: Path, seed: int) -> None:
    worst, ignored = _drive(tmp_path, 0.3, seed)
    assert worst < 0.06
    assert ignored[0] == 0  # the first scan: no prediction yet, every beam counts
    # the crate's beams (of 60): more as it grows nearer, never near the half that would mean a bad prediction
    assert ignored[1:] == sorted(ignored[1:]) and ignored[1] >= 10 and ignored[-1] <= 30


def test_with_every_beam_scored_the_same_crate_throws_the_estimate_off(tmp_path: Path) -> None:
    worst, ignored = _drive(tmp_path, 0.0, 0)  # unmapped 0: the behaviour before D235
    assert ignored == [0] * 25
    assert worst > 0.3


def test_a_scan_mostly_unlike_the_map_is_kept_whole(tmp_path: Path) -> None:
    """Unmapped walls on every side: the prediction is likelier wrong than the world so crowded (D235)."""
    file = room(tmp_path)
    ring = shapely.Point(1.0, 0.6).buffer(0.45).difference(shapely.Point(1.0, 0.6).buffer(0.4))
    world = grid(file, ring)
    nav = navigation(file, initialPose="1.0 0.6 0", initialSpread="0.05 0.05")
    for k in range(3):
        truth = (1.0, 0.6, 0.0)
        nav.process({"scan": scan(world, truth), "odom": odometry(truth)}, Context(k, 0.8 * k))
        assert nav.localizer is not None and nav.localizer.ignored == 0
