"""ROS 2 message type names in ``<Topic type>`` (schemas/kernel.xsd ``TopicTypeName``, issue L).

A topic may carry a ROS 2 type named ``package/msg/Name`` (thesis §4.4.1, the ROS MultiPeer
Architecture): a standard interface of ROS 2 Jazzy as the ``rosbags`` type store ships it
(std_msgs, geometry_msgs, sensor_msgs, nav_msgs, tf2_msgs, builtin_interfaces …), or a custom
one defined by the file ``package/msg/Name.msg`` next to the configuration file declaring the
topic (the layout of a ROS package, so an existing package's ``msg/`` folder can be copied in).
The loader only checks that the type exists; what its fields are and whether producers fit them
is ``verify``'s work (runtime.ros.config).
"""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

ROS_TYPE_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*/msg/[A-Za-z][A-Za-z0-9_]*$")


def is_ros_type(name: str) -> bool:
    """Whether ``name`` is spelt like a ROS 2 message type (``package/msg/Name``)."""
    return bool(ROS_TYPE_NAME.match(name))


@lru_cache(maxsize=1)
def standard_ros_types() -> frozenset[str]:
    """The message types of the ROS 2 Jazzy store of ``rosbags``."""
    from rosbags.typesys import Stores, get_typestore  # only configurations naming ROS types pay for it

    return frozenset(get_typestore(Stores.ROS2_JAZZY).fielddefs)


def custom_msg_file(name: str, declared_in: str | None) -> Path:
    """Where the ``.msg`` definition of custom type ``name`` is looked for: ``package/msg/Name.msg``
    in the folder of the file ``declared_in`` (the working directory without one)."""
    package, _, message = name.split("/")
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
        f"unknown ROS 2 message type {name!r}: not a ROS 2 Jazzy interface, and no custom definition "
        f"{path} (a custom type package/msg/Name is read from package/msg/Name.msg next to the configuration)"
    )
