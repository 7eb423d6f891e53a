"""Topics of a ROS 2 type travel as CDR on both transports (issue L point 1, decision D157).

:class:`CdrWire` is the :class:`runtime.network.wire.WireCodec` of a configuration: a topic whose
``<Topic type>`` names a ROS 2 type (``sensor_msgs/msg/LaserScan``, a custom ``pkg/msg/Name``)
leaves the process as the CDR bytes of that message (little endian, behind the ``00 01 00 00``
header, as ROS 2 and rosbag2 write it), on CKMultiPeer and on Zenoh alike; topics of CKM types stay
msgpack. Install it with :func:`install` once the transport is opened.

What is sent is what the recorder writes (:meth:`ConfigRosTypes.payload`: a value that is not a dict
stands for the message's ``data`` field, D131). What a remote subscriber gets back is the
:mod:`runtime.ros.convert` payload (a dict of the ROS fields, an Image as an array) in the codec's
plain form (:mod:`runtime.resources.codec`: arrays as ``{"~nd": …}``), the form services and vector
sensors publish locally, so every consumer decodes it alike (a stream, a service client, a
controller's input, a behavior; decision D194); a type whose only field is ``data``
(``std_msgs/msg/Float64``, ``String``, ``Bool`` …) gives back the bare value: a PID reading a number
from a ``std_msgs/msg/Float64`` topic gets a number, remote or local.

:meth:`CdrWire.topic_type` names the ROS type a configured topic carries, so a Smart Resource
service publishes its results under it (``runtime.resources.instance``, D194).
"""

from __future__ import annotations

from typing import Any

from ckmconf.model import System
from ckmconf.rostypes import is_ros_type

from ..network.api import Transport
from ..resources import codec
from .config import ConfigRosTypes, all_topics, plain
from .convert import decode_payload, to_message
from .types import RosTypeError

CDR = "cdr"


class CdrWire:
    """Serialises every ROS 2 type of a configuration's type store as CDR (see the module docstring).

    Args:
        types: the configuration's ROS types (custom ``.msg`` files and generated ``ckm_msgs``).
        system: the configuration, whose topics :meth:`topic_type` names (none without it).
    """

    name = CDR

    def __init__(self, types: ConfigRosTypes, system: System | None = None) -> None:
        self.types = types
        self._bare: dict[str, bool] = {}
        self._topics: dict[str, str] = {}
        for topic, _ in all_topics(system) if system is not None else ():
            if not self.encodes(topic.type):
                continue
            known = self._topics.setdefault(topic.name, topic.type)
            if known != topic.type:  # two nodes' internal topics of one name: no single type
                self._topics[topic.name] = ""
        self._topics = {name: kind for name, kind in self._topics.items() if kind}

    def encodes(self, type_name: str) -> bool:
        """True for a ROS 2 type (``pkg/msg/Name``) the configuration's type store knows (§4.4.1)."""
        return is_ros_type(type_name) and type_name in self.types.ros

    def encode(self, type_name: str, value: Any) -> bytes:
        """``value`` as a CDR message of ``type_name``; ValueError naming the type when it does not fit."""
        ros = self.types.ros
        try:
            return ros.encode(type_name, to_message(ros, type_name, self.types.payload(type_name, plain(value))))
        except RosTypeError as error:
            raise ValueError(f"not a {type_name}: {error}") from error

    def decode(self, type_name: str, data: bytes) -> Any:
        """The CKM payload of CDR ``data`` in the codec's plain form; a type whose only field is
        ``data`` gives that field bare."""
        return codec.encode(self.payload_of(type_name, data))

    def payload_of(self, type_name: str, data: bytes) -> Any:
        """The :mod:`runtime.ros.convert` payload of CDR ``data`` (arrays as arrays), bare as :meth:`decode`."""
        payload = decode_payload(self.types.ros, type_name, data)  # RosTypeError is a ValueError
        bare = self._bare.get(type_name)
        if bare is None:
            bare = self._bare[type_name] = [name for name, _ in self.types.ros.fields(type_name)] == ["data"]
        return payload["data"] if bare and isinstance(payload, dict) else payload

    def topic_type(self, topic: str) -> str | None:
        """The ROS 2 type the configured topic ``topic`` carries (None: not one, or declared with two types)."""
        return self._topics.get(topic)


def install(transport: Transport, system: System) -> CdrWire | None:
    """Give ``transport`` the CDR codec when ``system`` has a topic of a ROS 2 type; returns it."""
    if not any(is_ros_type(topic.type) for topic, _ in all_topics(system)):
        return None
    wire = CdrWire(ConfigRosTypes(system), system)
    transport.codec = wire
    return wire
