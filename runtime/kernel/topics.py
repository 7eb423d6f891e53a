"""The network name and QoS of a node's topic (kernel.xsd ``TopicType``, §3.1.2.10).

A node sees its own ``<Topic>`` elements first, then the system's external ones. An internal
topic never leaves its node, so on the network it has a node-local name, ``/NODE/~name``; an
external one keeps its name. The node and code delegation (which names the giver's topics on the
taker) both name topics here.
"""

from __future__ import annotations

from ckmconf.model import Node, System, Topic

from ..network.api import TopicQoS


def declared_topic(node: Node, system: System, name: str) -> Topic | None:
    """The ``<Topic>`` called ``name`` as ``node`` sees it: its own first, then any external one."""
    found = next((t for t in node.topics if t.name == name), None)
    if found is None:
        external = [*system.topics, *(t for n in system.nodes for t in n.topics if t.scope == "external")]
        found = next((t for t in external if t.name == name), None)
    return found


def topic_qos(node: str, topic: Topic) -> TopicQoS:
    """The QoS of ``topic`` with its network name, as seen from the node called ``node``."""
    qos = TopicQoS.of(topic)
    if topic.scope == "internal":  # internal topics never leave the node: give them a node-local name
        qos = TopicQoS(
            f"/{node}/~{topic.name.lstrip('/')}", qos.type, qos.reliability, qos.history, qos.deadline, qos.lifespan
        )
    return qos
