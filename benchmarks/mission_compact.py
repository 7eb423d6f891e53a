"""A compact copy of the use case's laboratory, for short missions (issue K point 7, thesis §7.3–7.5).

The whole configuration directory is copied (its Parts include each other by relative ``href``)
and, in the copy, only the *layout* changes — every node, channel, service, behavior, mission and
plan stays as the lab has it, so a run of the copy exercises the same system:

- the ``drop_table`` Object stands 1.4 m left of the workbench (:data:`DROP_TABLE`) and the
  ``HomeArea`` becomes the floor in front of it (:data:`HOME_AREA`);
- the Turtlebot starts in that area (:data:`START`): every ``sim`` HWChannel of body
  ``turtlebot`` that gives a ``pose`` Param, and the Navigation resource's ``initialPose``;
- NAV_HOME's goal and DOCK's docking pose move with the drop table, at the same offsets from its
  front edge as in the lab (0.30 m and 0.18 m, D196);
- optionally, the ``<Network>``'s discovery and base ports (a test's private network).

A fetch is then about 1.5 m each way instead of 8 m: the mission takes under a minute of
simulated time. :func:`compact` validates the copy with :func:`ckmconf.load`. Decision D205.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import ckmconf
from benchmarks.mission_random import NS, Q, param_values, params_named, set_param, sim_channels

ROBOT = "turtlebot"  # the lab's mobile manipulator (this layout is the lab's own)
NAVIGATION_PARAM = "initialPose"  # its Navigation resource's start estimate (amcl-navigation)

DROP_TABLE = (6.2, 5.6)  # the drop table's centre (m); its front edge is 0.3 m below, at y 5.3
HOME_AREA = ((5.4, 4.2), (6.9, 4.2), (6.9, 5.9), (5.4, 5.9))
START = "6.3 4.6 0.785"  # x y yaw of the Turtlebot, inside HOME_AREA and clear of both tables
NAV_HOME_GOAL = "6.2 5.0 1.5708"  # facing the drop table, 0.30 m from its front edge (behaviors.xml NAV_HOME)
DOCK_POSE = "6.2 5.12 1.5708"  # 0.18 m from its front edge (behaviors.xml DOCK)


def _move_drop_table(root: ET.Element) -> bool:
    changed = False
    for obj in root.iter(Q + "Object"):
        if obj.get("name") == "drop_table" and (pose := obj.find(Q + "Pose")) is not None:
            pose.set("x", str(DROP_TABLE[0]))
            pose.set("y", str(DROP_TABLE[1]))
            changed = True
    for area in root.iter(Q + "Area"):
        if area.get("name") == "HomeArea":
            for vertex in area.findall(Q + "Vertex"):
                area.remove(vertex)
            for x, y in HOME_AREA:
                ET.SubElement(area, Q + "Vertex", {"x": str(x), "y": str(y)})
            changed = True
    return changed


def _move_start(root: ET.Element) -> bool:
    changed = False
    for _, channel in sim_channels(root):
        values = param_values(channel)
        if values.get("body") == ROBOT and values.get("pose"):
            set_param(channel, "pose", START)
            changed = True
    for _, param in params_named(root, "SmartResource", NAVIGATION_PARAM):
        param.set("value", START)
        changed = True
    return changed


def _move_home_goals(root: ET.Element) -> bool:
    changed = False
    for behavior in root.iter(Q + "Behavior"):
        name = behavior.get("name")
        if name == "NAV_HOME":
            for configure in behavior.iter(Q + "Configure"):
                if configure.get("parameter") == "goal":
                    configure.set("value", NAV_HOME_GOAL)
                    changed = True
        elif name == "DOCK":
            for param in behavior.findall(Q + "Param"):
                if param.get("name") == "pose":
                    param.set("value", DOCK_POSE)
                    changed = True
    return changed


def _move_ports(root: ET.Element, ports: tuple[int, int]) -> bool:
    networks = list(root.iter(Q + "Network"))
    for network in networks:
        network.set("discoveryPort", str(ports[0]))
        network.set("basePort", str(ports[1]))
    return bool(networks)


def compact(config: Path, out_dir: Path, ports: tuple[int, int] | None = None) -> Path:
    """Copy ``config``'s directory to ``out_dir`` with the compact layout; the copy's System file.

    ``ports`` (discovery, base) moves the copy's ``<Network>`` off the lab's ports, so that a test
    running the copy cannot meet a lab run on the same machine.

    Raises:
        ValueError: the configuration lacks what is moved (the drop table, HomeArea, the robot's
            start pose, NAV_HOME or DOCK); ckmconf.ConfigError: the copy is invalid.
    """
    config = Path(config)
    if out_dir.exists():
        shutil.rmtree(out_dir)
    shutil.copytree(config.parent, out_dir)
    ET.register_namespace("", NS)
    moved = {"drop table": False, "start": False, "home goals": False}
    for path in sorted(out_dir.glob("*.xml")):
        tree = ET.parse(path)
        root = tree.getroot()
        changes = {"drop table": _move_drop_table(root), "start": _move_start(root),
                   "home goals": _move_home_goals(root)}  # fmt: skip
        if ports is not None and _move_ports(root, ports):
            changes["ports"] = True
        if any(changes.values()):
            tree.write(path, encoding="UTF-8", xml_declaration=True)
        moved = {k: moved[k] or changes[k] for k in moved}  # the ports are optional
    missing = [k for k, done in moved.items() if not done]
    if missing:
        raise ValueError(f"{config}: nothing to move for the compact layout: {', '.join(missing)}")
    copy = out_dir / config.name
    ckmconf.load(copy)  # the copy must be a valid configuration before anything runs it
    return copy
