"""The process graph SRFlowGen walks (thesis §5.4, eq. 5.2–5.4, Algorithm 2's EvalFlow).

Processes are the services of the Smart Resources, the nodes' controllers and the sources (node
sensors, behavior outputs, plan signals); :class:`ProcessGraph` links them process → topic →
process, from each ``Output``/``Sensor`` topic to each ``Input`` reading it, an internal topic
resolved on its own node (D10). It gives the chains ``R_1:k`` from a variable back to its sources
and ``k``, the processing steps on the longest one (a feedback loop's steps counted once).
"""

from __future__ import annotations

import networkx as nx  # type: ignore[import-untyped]

from ckmconf.binding import Record
from ckmconf.model import Service, System

MAX_CHAINS = 32
"""Chains listed per variable; the probability and k always cover the whole upstream graph."""


class ProcessGraph:
    """The system's processes and topics (eq. 5.2–5.4) as a networkx DiGraph: producer → topic → consumer."""

    def __init__(self, system: System) -> None:
        self.system = system
        self.graph = nx.DiGraph()
        self.services: dict[str, Service] = {}
        self.ports: dict[tuple[str, str], Record] = {}  # (consumer, topic node) → its Input record
        internal = {(n.name, t.name) for n in system.nodes for t in n.topics if t.scope == "internal"}
        self._internal = internal
        for node in system.nodes:
            for sensor in node.sensors:
                self._produce(f"sensor:{node.name}/{sensor.name}", node.name, sensor.topic)
            for controller in node.controllers:
                step = f"controller:{node.name}/{controller.name}"
                for port in controller.inputs:
                    self._consume(step, node.name, port.topic, port)
                for out in controller.outputs:
                    self._produce(step, node.name, out.topic)
        for resource in system.resources:
            for service in resource.services:
                step = f"service:{resource.name}.{service.name}"
                self.services[f"{resource.name}.{service.name}"] = service
                self.graph.add_node(step)
                for service_in in service.inputs:
                    self._consume(step, resource.node, service_in.topic, service_in)
                for service_out in service.outputs:
                    self._produce(step, resource.node, service_out.topic)
        for behavior in system.behaviors:
            for output in behavior.outputs:
                if output.topic is not None:
                    self._produce(f"behavior:{behavior.name}", None, output.topic)
        for plan in system.plans:
            for signal in plan.signals:
                self._produce(f"signal:{plan.name}/{signal.name}", None, plan.signal_topic(signal))

    def topic(self, node: str | None, name: str) -> str:
        """The graph node of a topic as seen from a node (internal topics are the node's own, D10)."""
        return f"topic:{node}/{name}" if node is not None and (node, name) in self._internal else f"topic:{name}"

    def _produce(self, process: str, node: str | None, topic: str) -> None:
        self.graph.add_edge(process, self.topic(node, topic))

    def _consume(self, process: str, node: str | None, topic: str, port: Record) -> None:
        key = self.topic(node, topic)
        self.graph.add_edge(key, process)
        self.ports.setdefault((process, key), port)

    def longest(self, upstream: set[str], head: str) -> int:
        """k: processing steps on the longest chain into ``head``, each step of a loop counted once."""
        sub = self.graph.subgraph(upstream)
        dag = nx.condensation(sub)
        members = dag.graph["mapping"]
        weight = {c: sum(1 for n in dag.nodes[c]["members"] if n.startswith(("service:", "controller:"))) for c in dag}
        best: dict[int, int] = {}
        for component in nx.topological_sort(dag):
            best[component] = weight[component] + max((best[p] for p in dag.predecessors(component)), default=0)
        return best[members[head]]

    def chains(self, head: str, k_max: int) -> tuple[tuple[tuple[str, ...], ...], bool]:
        """Every chain from ``head`` back to a source (at most MAX_CHAINS), and whether some were left out."""
        found: list[tuple[str, ...]] = []
        truncated = False

        def walk(node: str, path: tuple[str, ...], seen: frozenset[str]) -> None:
            nonlocal truncated
            if len(found) >= MAX_CHAINS:
                truncated = True
                return
            label = node_label(node)
            if node in seen:
                found.append((*path, f"{label} (loop)"))
                return
            path = (*path, label) if label else path
            topics = self._topics_into(node)
            if not topics or len(path) > k_max + 1:  # a source, or far enough to show k >= K_max
                found.append(path)
                return
            for topic in topics:  # in the order the inputs are declared
                producers = list(self.graph.predecessors(topic))
                if not producers:
                    found.append((*path, f"? {topic.removeprefix('topic:')}"))
                for producer in producers:
                    walk(producer, path, seen | {node})

        walk(head, (), frozenset())
        return tuple(dict.fromkeys(found)), truncated

    def _topics_into(self, node: str) -> list[str]:
        return [node] if node.startswith("topic:") else list(self.graph.predecessors(node))


def node_label(node: str) -> str:
    """How a chain shows a graph node: a service or controller by name, a topic not at all, others with their kind."""
    kind, _, name = node.partition(":")
    return {"service": name, "controller": name, "topic": ""}.get(kind, f"{name} ({kind})")
