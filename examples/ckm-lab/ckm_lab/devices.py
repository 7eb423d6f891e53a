"""The lab's hardware as the simulator's Python classes take it (thesis §7.1, Table 7.2).

The toolkit's simulator classes (:mod:`plugins.sim.sensors`, :mod:`plugins.sim.robots`,
:mod:`plugins.sim.head`) have no device defaults: a scanner, camera, base or head is whatever its
caller says. The lab's tests and benchmarks build the lab's own devices from these, the values
configs/usecase/nodes.xml gives its channels.
"""

from __future__ import annotations

from typing import Any

HOKUYO: dict[str, Any] = {"beams": 683, "fov": 4.1888, "range_min": 0.02, "range_max": 5.6}
"""The Turtlebot's Hokuyo URG-04LX: 683 steps over 240°, 0.02–5.6 m."""

XTION_FOV = 1.0123
"""The Turtlebot's Asus Xtion Pro Live: 58° horizontal field of view (rad)."""

NAO_TOP_FOV = 0.8331
"""The Nao's top camera: 47.7° horizontal field of view (rad)."""

KOBUKI: dict[str, Any] = {"left": "wheel_left_joint", "right": "wheel_right_joint", "wheel_radius": 0.035,
                          "wheel_base": 0.230, "ticks_per_rev": 2578.33}
"""The Turtlebot's Kobuki base: its wheel joints, radius and track (m) and encoder ticks per turn."""

NAO_HEAD: dict[str, Any] = {"yaw": "HeadYaw", "pitch": "HeadPitch"}
"""The Nao's head joints."""
