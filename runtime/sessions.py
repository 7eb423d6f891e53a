"""Run-wide sessions of hardware backends: ckm-run's generic hook (issue J point 5, D102).

A backend class registered as ``hardware.KIND`` may define a classmethod

    run_session(system, config, run_dir, nodes, failed) -> context manager

that ``ckm-run``'s host (:meth:`runtime.host.Host.start_sessions`) enters before it builds any
node or starts any partition and leaves after every node and partition has stopped: a simulator
serving the channels of every process of the run (the ``hardware.sim`` world server), a bus
daemon… ``nodes`` are the nodes this process runs;
``failed(message)`` tells the run that the session broke while it lasted (ckm-run then prints the
message, stops and exits 5). The runtime finds the backends through the registry, so it imports no
plugin itself. Each backend kind used by the nodes' channels is entered once, in name order.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from pathlib import Path

from ckmconf.model import Node, System

from .registry import Registry, default_registry


class HardwareSessions:
    """The ``run_session`` hooks of the backends the nodes use, entered by :meth:`start`, left by
    :meth:`stop` (idempotent; also leaves those entered before a failing one)."""

    def __init__(
        self,
        system: System,
        config: Path,
        run_dir: Path,
        nodes: Sequence[Node],
        failed: Callable[[str], None],
        registry: Registry | None = None,
    ) -> None:
        self.system, self.config, self.run_dir, self.nodes, self.failed = system, config, run_dir, nodes, failed
        self.registry = registry or default_registry()
        self._stack = contextlib.ExitStack()

    def start(self) -> None:
        """Enter the session of each backend kind the nodes' channels use, in name order."""
        for kind in sorted({channel.backend for node in self.nodes for channel in node.channels}):
            backend = self.registry.find("hardware", kind)  # an unknown kind is NodeRuntime's error to report
            hook = getattr(backend, "run_session", None)
            if hook is not None:
                self._stack.enter_context(hook(self.system, self.config, self.run_dir, list(self.nodes), self.failed))

    def stop(self) -> None:
        """Leave every session entered, the last first."""
        self._stack.close()
