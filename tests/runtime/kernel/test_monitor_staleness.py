"""A Monitor's staleness Alarm (kernel.xsd ``Alarm measure="staleness"``, §3.1.2.4) on a topic that was
never published counts its age from the watch's first look, so the topic's producer has the alarm's own
limit to start, and a producer that never starts still raises it (D311)."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from runtime.kernel.node import NodeRuntime
from tests import waiting
from tests.runtime.kernel.conftest import running_node

until = functools.partial(waiting.until, interval=0.01)

SILENT = """<System xmlns="urn:ckm:1" version="1.0" name="silent">
  <Node name="n">
    <Topic name="heartbeat" type="float64" scope="internal"/>
    <Monitor period="0.05">
      <Alarm name="heartbeat_lost" measure="staleness" topic="heartbeat" above="0.4" severity="warning"/>
    </Monitor>
  </Node>
</System>"""


@pytest.fixture
def runtime(tmp_path: Path) -> Iterator[NodeRuntime]:
    with running_node(SILENT, tmp_path, "staleness-test") as (node, _):
        yield node


def test_a_topic_never_published_is_stale_only_after_the_alarms_limit(runtime: NodeRuntime) -> None:
    monitor = runtime.monitor
    assert monitor is not None
    state = monitor.alarms["heartbeat_lost"]
    seen: list[tuple[float, bool]] = []

    def raised() -> bool:
        seen.append((state.value, state.active))
        return state.active

    assert until(raised, timeout=15)
    before = [value for value, active in seen if not active]
    assert before and all(0.0 <= value <= 0.4 for value in before)  # a finite age from the first look
    assert math.isfinite(state.value) and state.value > 0.4  # raised once the limit passed, not at start
    assert state.raised == 1
