"""The ROS 2 graph as rmw_zenoh announces it: topics with their types, from liveliness tokens (issue L point 4).

ROS 2 nodes running rmw_zenoh declare a liveliness token per node and per endpoint (docs/ros.md,
rmw_zenoh ``docs/design.md`` at commit ``99a6a2bd``)::

    @ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node>
             [/<topic>/<dds type>/<type hash>/<qos>]          (endpoints only; names with / as %)

where ``kind`` is ``NN`` (node), ``MP`` (publisher), ``MS`` (subscription), ``SS`` (service),
``SC`` (client). :class:`RosGraph` keeps the endpoints whose tokens are alive and lists the topics
seen with their ROS types (:meth:`RosGraph.topics`), the editor's ROS bridge view shows them
(editor/views/ros_bridge.py). This is a protocol module with no dependency beyond Zenoh, so the
editor may import it (the editor-protocols contract); the full codec of tokens, QoS strings and
attachments is :mod:`runtime.ros.rmw_zenoh`, against which the tests check this reading.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from typing import Any

import zenoh

ADMIN_SPACE = "@ros2_lv"
KINDS = {"MP": "publisher", "MS": "subscription", "SS": "service", "SC": "client"}
_DDS = re.compile(r"([A-Za-z][A-Za-z0-9_]*)::(msg|srv|action)::dds_::([A-Za-z][A-Za-z0-9_]*)_")


@dataclass(frozen=True)
class GraphEndpoint:
    """One endpoint of the ROS graph: its topic (or service), ROS type, kind and node."""

    domain_id: int
    topic: str
    type_name: str
    kind: str  # publisher, subscription, service or client
    node: str  # fully qualified: /namespace/name


@dataclass(frozen=True)
class GraphTopic:
    """A topic or service seen in the graph, with its type and who offers and uses it."""

    domain_id: int
    name: str
    type_name: str
    publishers: int
    subscriptions: int
    services: int
    clients: int
    nodes: tuple[str, ...]


def _demangle(chunk: str) -> str:
    return "" if chunk == "%" else chunk.replace("%", "/")


def parse_endpoint(keyexpr: str) -> GraphEndpoint | None:
    """The endpoint an rmw_zenoh liveliness token announces; None for a node's token or anything else."""
    parts = keyexpr.split("/")
    if len(parts) != 13 or parts[0] != ADMIN_SPACE or parts[5] not in KINDS or not parts[1].isdigit():
        return None
    match = _DDS.fullmatch(parts[10])
    if match is None:
        return None
    namespace, name = _demangle(parts[7]).strip("/"), _demangle(parts[8])
    node = f"/{namespace}/{name}" if namespace else f"/{name}"
    return GraphEndpoint(int(parts[1]), _demangle(parts[9]), "/".join(match.groups()), KINDS[parts[5]], node)


class RosGraph:
    """The endpoints whose liveliness tokens are alive, fed by :meth:`on_token` (thread-safe).

    Args:
        domain_id: only this ROS domain (all by default).
    """

    def __init__(self, domain_id: int | None = None) -> None:
        self.domain_id = domain_id
        self._alive: dict[str, GraphEndpoint] = {}
        self._lock = threading.Lock()

    def on_token(self, keyexpr: str, alive: bool) -> None:
        """A token appeared (``alive``) or went away."""
        endpoint = parse_endpoint(keyexpr)
        if endpoint is None or (self.domain_id is not None and endpoint.domain_id != self.domain_id):
            return
        with self._lock:
            if alive:
                self._alive[keyexpr] = endpoint
            else:
                self._alive.pop(keyexpr, None)

    def on_sample(self, sample: zenoh.Sample) -> None:
        """A Zenoh liveliness sample: PUT when a token is declared, DELETE when it goes."""
        self.on_token(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

    def watch(self, session: zenoh.Session) -> Any:
        """Follow the tokens of ``session``'s Zenoh network (those alive now too); undeclare the
        returned subscriber to stop."""
        domain = "*" if self.domain_id is None else str(self.domain_id)
        return session.liveliness().declare_subscriber(f"{ADMIN_SPACE}/{domain}/**", self.on_sample, history=True)

    def topics(self) -> list[GraphTopic]:
        """Every topic and service seen, by domain, name and type (a name with two types is two rows)."""
        with self._lock:
            endpoints = list(self._alive.values())
        groups: dict[tuple[int, str, str], list[GraphEndpoint]] = {}
        for endpoint in endpoints:
            groups.setdefault((endpoint.domain_id, endpoint.topic, endpoint.type_name), []).append(endpoint)
        rows = []
        for (domain, name, type_name), members in sorted(groups.items()):
            count = {kind: sum(1 for m in members if m.kind == kind) for kind in KINDS.values()}
            rows.append(
                GraphTopic(
                    domain,
                    name,
                    type_name,
                    count["publisher"],
                    count["subscription"],
                    count["service"],
                    count["client"],
                    tuple(sorted({m.node for m in members})),
                )
            )
        return rows
