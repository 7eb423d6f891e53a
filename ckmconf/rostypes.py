"""ROS 2 message type names in ``<Topic type>`` (schemas/kernel.xsd ``TopicTypeName``, issue L).

A topic may carry a ROS 2 type named ``package/msg/Name`` (thesis §4.4.1, the ROS MultiPeer
Architecture): a standard interface of ROS 2 Jazzy as the ``rosbags`` type store ships it
(std_msgs, geometry_msgs, sensor_msgs, nav_msgs, tf2_msgs, builtin_interfaces …), or a custom
one defined by the file ``package/msg/Name.msg`` next to the configuration file declaring the
topic (the layout of a ROS package, so an existing package's ``msg/`` folder can be copied in), or
one of the packages CKM ships (:data:`SHIPPED_PACKAGES`: ``ckm_interfaces``, the message types of
the standard service interfaces that ROS 2 has no standard type for, docs/interfaces.md; D278).
The loader only checks that the type exists; what its fields are and whether producers fit them
is ``verify``'s work (runtime.ros.config).
"""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

ROS_TYPE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*$")

SHIPPED = Path(__file__).parent / "ros"
"""Where the ROS 2 packages CKM ships live (``ckm_interfaces/msg/*.msg``, with its package.xml)."""
SHIPPED_PACKAGES = frozenset(p.name for p in SHIPPED.iterdir() if (p / "msg").is_dir()) if SHIPPED.is_dir() else (
    frozenset())
"""The packages of :data:`SHIPPED`: their types are known to every configuration, wherever it lives."""


def is_ros_type(name: str) -> bool:
    """Whether ``name`` is spelt like a ROS 2 message type (``package/msg/Name``)."""
    return bool(ROS_TYPE_NAME.match(name))


@lru_cache(maxsize=1)
def standard_ros_types() -> frozenset[str]:
    """The message types of the ROS 2 Jazzy store of ``rosbags``."""
    from rosbags.typesys import Stores, get_typestore  # only configurations naming ROS types pay for it

    return frozenset(get_typestore(Stores.ROS2_JAZZY).fielddefs)


def shipped_ros_types() -> list[str]:
    """The message types of the packages CKM ships (``ckm_interfaces/msg/Detections`` …), sorted."""
    return sorted(f"{package}/msg/{path.stem}" for package in SHIPPED_PACKAGES
                  for path in (SHIPPED / package / "msg").glob("*.msg"))


def custom_msg_file(name: str, declared_in: str | None) -> Path:
    """Where the ``.msg`` definition of custom type ``name`` is looked for: in the shipped package
    of its name (:data:`SHIPPED_PACKAGES`, which a configuration's own folder cannot shadow), else
    ``package/msg/Name.msg`` in the folder of the file ``declared_in`` (the working directory without one)."""
    package, _, message = name.split("/")
    if package in SHIPPED_PACKAGES:
        return SHIPPED / package / "msg" / f"{message}.msg"
    base = Path(declared_in).parent if declared_in and not declared_in.startswith("<") else Path(".")
    return base / package / "msg" / f"{message}.msg"


def ros_type_problem(name: str, declared_in: str | None) -> str | None:
    """Why ROS type ``name`` cannot be used (None when it is a standard type or its file exists)."""
    if not is_ros_type(name):
        return f"{name!r} is not a ROS 2 message type name (package/msg/Name)"
    if name in standard_ros_types():
        return None
    path = custom_msg_file(name, declared_in)
    if path.is_file():
        return None
    return (
        f"unknown ROS 2 message type {name!r}: not a ROS 2 Jazzy interface, not one of CKM's "
        f"{', '.join(sorted(SHIPPED_PACKAGES))}, and no custom definition "
        f"{path} (a custom type package/msg/Name is read from package/msg/Name.msg next to the configuration)"
    )
