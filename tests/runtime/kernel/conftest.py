"""Shared for the kernel's tests: one node built from an XML text, running on a private network."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import ckmconf
from runtime.kernel.node import NodeRuntime
from runtime.network import Transport, open_transport
from tests.runtime.network.conftest import private_network


@contextlib.contextmanager
def running_node(text: str, directory: Path, name: str) -> Iterator[tuple[NodeRuntime, Transport]]:
    """The first node of the system ``text`` (written to ``directory``), set up and started; stopped after."""
    transport = open_transport(private_network(), name=name)
    transport.setup()
    transport.start()
    path = directory / f"{name}.xml"
    path.write_text(text)
    system = ckmconf.load(path)
    runtime = NodeRuntime(system.nodes[0], system, transport)
    runtime.setup()
    runtime.start()
    try:
        yield runtime, transport
    finally:
        runtime.stop()
        transport.stop()
