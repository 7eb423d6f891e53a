"""Test plugins for plugin delegation, and a taker node to run in another process.

``python -m tests.runtime.resources.plugin_host_peer GROUP DISCOVERY_PORT BASE_PORT NODE`` joins the
private loopback network of a test, runs a PluginHost for NODE and prints ``ready``; it exits when
its stdin closes (the test ended or died) or after ``LIFETIME`` seconds, whichever comes first.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from ckmconf.model.resources import Plugin
from plugins.processing.image import Resize
from runtime.network import open_transport
from runtime.registry import Registry
from runtime.resources.delegation import PluginHost
from runtime.resources.spt import Context, ProcessingPlugin

LIFETIME = 60.0


class Accumulate(ProcessingPlugin):
    """Stateful: the running mean of the images seen so far, and their count.

    Its output depends on every earlier frame, so any state lost or applied twice in a handover
    changes every later output. ``calls`` counts the calls made on this instance (not state).
    """

    PARAMS: ClassVar[Mapping[str, Any]] = {"weight": 1.0}

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.total: npt.NDArray[np.float64] | None = None
        self.count = 0
        self.calls = 0

    def process(self, data: Any, context: Context) -> Any:
        self.calls += 1
        image = np.asarray(data, dtype=np.float64) * self.params["weight"]
        self.total = image if self.total is None else self.total + image
        self.count += 1
        return {"mean": self.total / self.count, "count": self.count, "frame": (context.frame, np.int64(self.count))}

    def state(self) -> dict[str, Any]:
        return {"total": self.total, "count": self.count}

    def restore(self, state: Mapping[str, Any]) -> None:
        self.total = state.get("total")
        self.count = int(state.get("count", 0))


class FailingSetup(ProcessingPlugin):
    """Cannot be set up (a device missing on the taker)."""

    def setup(self) -> None:
        raise OSError("no camera on this node")

    def process(self, data: Any, context: Context) -> Any:
        return data


def same(a: Any, b: Any) -> bool:
    """Equal values of the same types all the way down (arrays: dtype, shape and contents)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return bool(a == b)


def registry(*, accumulate: bool = True) -> Registry:
    """A private registry: resize (the real image plugin), accumulate, failing-setup."""
    made = Registry(load_entry_points=False)
    made.register("plugin", "resize", Resize)
    made.register("plugin", "failing-setup", FailingSetup)
    if accumulate:
        made.register("plugin", "accumulate", Accumulate)
    return made


def main(argv: list[str]) -> int:
    from tests.runtime.network.conftest import private_network

    group, discovery, base, node = argv
    network = private_network(group=group, discovery_port=int(discovery), base_port=int(base))
    closed = threading.Event()

    def watch_stdin() -> None:  # EOF: the test is over (or dead), so is this taker
        sys.stdin.read()
        closed.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    with open_transport(network, name=node) as transport, PluginHost(transport, node, registry()):
        print("ready", flush=True)
        closed.wait(LIFETIME)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
