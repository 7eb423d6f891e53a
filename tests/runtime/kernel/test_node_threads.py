"""NodeRuntime's threading model (issue O point 2): controllers added, removed, switched and counted from
several threads while the scheduler runs them; the node's lock keeps every iteration whole and exactly one
controller drives the shared output at the end."""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from runtime.kernel.node import NodeRuntime
from tests.runtime.kernel.conftest import running_node
from tests.runtime.kernel.test_node import SWITCHING

ROUNDS = 60

pytestmark = pytest.mark.usefixtures("switching_often")


@pytest.fixture
def node(tmp_path: Path) -> Iterator[NodeRuntime]:
    with running_node(SWITCHING, tmp_path, "node-threads") as (runtime, _):
        yield runtime


def test_controllers_change_from_many_threads_while_the_node_runs_and_reports(node: NodeRuntime) -> None:
    template = node.node.controllers[1]  # "b": a PID on the same output as "a"
    failures: list[BaseException] = []
    go = threading.Barrier(4)

    def guarded(work: Callable[[], None]) -> None:
        def run() -> None:
            go.wait(10)
            try:
                work()
            except BaseException as error:  # reported by the assertion below
                failures.append(error)
        threading.Thread(target=run, daemon=True).start()

    def churn(prefix: str) -> None:
        for n in range(ROUNDS):
            name = f"{prefix}{n}"
            node.add_controller(dataclasses.replace(template, name=name, active=True))
            node.switch("a", reason="test")
            node.remove_controller(name)

    def count() -> None:
        for _ in range(ROUNDS * 20):
            figures = node.statistics()["controllers"]
            assert "a" in figures and "b" in figures

    events: list[dict[str, object]] = []
    node.event_sinks.append(events.append)
    threads_before = set(threading.enumerate())
    guarded(lambda: churn("added_x"))
    guarded(lambda: churn("added_y"))
    guarded(count)
    go.wait(10)
    for thread in set(threading.enumerate()) - threads_before:
        thread.join(60)
    assert not failures, failures
    assert set(node.controllers) == {"a", "b"}
    assert {"n.a", "n.b"} <= set(node.scheduler.tasks)
    assert not [name for name in node.scheduler.tasks if name.startswith("n.added_")]  # every removed task gone
    active = [name for name, control in node.controllers.items() if control.active]
    assert active == ["a"]  # every added one was removed; the last switch gave the output back to "a"
    removed = [e for e in events if e["kind"] == "controller-removed"]
    assert len(removed) == 2 * ROUNDS
