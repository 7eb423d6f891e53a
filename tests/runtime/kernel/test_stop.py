"""A stop always leaves the actuators safe, and a long-running node's buffers are bounded (issue G)."""

from __future__ import annotations

import functools
import threading
from collections import deque
from collections.abc import Callable, Iterator

import pytest
from hypothesis import given
from hypothesis import strategies as st

import ckmconf
from runtime.kernel import node as node_module
from runtime.kernel import scheduler as scheduler_module
from runtime.kernel.node import NodeRuntime
from runtime.kernel.scheduler import BUSY_LIMIT, IDLE_WINDOW, SAMPLES_KEPT, Ring, Scheduler, Task
from runtime.network import Transport, open_transport
from tests import waiting
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

CLOSED_LOOP = REPO / "configs" / "examples" / "closed_loop.xml"


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="stop-test")
    running.setup()
    running.start()
    yield running
    running.stop()


def ran(task: Task, times: int) -> bool:
    return task.stats.releases > times


until = functools.partial(waiting.until, interval=0.01)  # this file's polling period


def test_a_stop_during_heavy_statistics_traffic_leaves_every_actuator_safe(transport: Transport) -> None:
    """The old stop walked the jitter deque while the scheduler appended to it (4 runs in 20 crashed
    with "deque mutated during iteration" before driving the safe value); repeated to catch it."""
    system = ckmconf.load(CLOSED_LOOP)
    record = system.nodes[0]
    for attempt in range(25):
        node = NodeRuntime(record, system, transport)
        node.setup()
        node.start()
        for index in range(4):  # 1 kHz tasks: the jitter deques change all the time
            node.scheduler.add(Task(f"{record.name}.busy{index}", 0.001, lambda: None))
        errors: list[BaseException] = []
        done = threading.Event()

        def hammer(
            node: NodeRuntime = node, done: threading.Event = done, errors: list[BaseException] = errors
        ) -> None:
            while not done.is_set():
                try:
                    node.statistics()
                except BaseException as error:  # any error here is the failure
                    errors.append(error)
                    return

        readers = [threading.Thread(target=hammer, daemon=True) for _ in range(3)]
        for reader in readers:
            reader.start()
        busy0 = node.scheduler.tasks[f"{record.name}.busy0"]
        assert until(functools.partial(ran, busy0, 50))
        node.stop()
        done.set()
        for reader in readers:
            reader.join(10)
        assert not errors, f"attempt {attempt}: {errors[0]!r}"
        for name, actuation in node.actuators.items():
            assert actuation.mode == "safe" and actuation.latched, f"attempt {attempt}: {name} not safe"
            assert actuation.value == actuation.record.safe_value
        assert node.statistics()["tasks"], "the final statistics were not kept"


def test_a_failing_stop_step_does_not_skip_the_others(transport: Transport) -> None:
    system = ckmconf.load(CLOSED_LOOP)
    node = NodeRuntime(system.nodes[0], system, transport)
    node.setup()
    node.start()

    def broken(*_: object) -> dict[str, object]:
        raise RuntimeError("statistics broke")

    node.scheduler.statistics = broken  # type: ignore[method-assign,assignment]
    closed: list[str] = []
    for name, backend in node.backends.items():
        stop = backend.stop

        def recording(stop: Callable[[], None] = stop, name: str = name) -> None:
            closed.append(name)
            stop()

        backend.stop = recording  # type: ignore[method-assign]
    node.stop()  # logs the failure, raises nothing
    assert all(a.mode == "safe" for a in node.actuators.values())
    assert sorted(closed) == sorted(node.backends)  # the hardware still closed


def test_the_scheduler_keeps_only_the_last_idle_window_of_runs() -> None:
    """Scheduler._busy used to gain an entry per run forever (only idle_share() trimmed it)."""
    scheduler = Scheduler("bounded")
    task = scheduler.add(Task("fast", 0.0005, lambda: None))  # no optional part: idle_share is never asked
    scheduler.start()
    try:
        assert until(lambda: task.stats.releases > 3000, timeout=60)
        with scheduler._lock:
            busy = list(scheduler._busy)
        assert busy and busy[0][0] >= busy[-1][0] - IDLE_WINDOW  # trimmed on every run
        assert scheduler._busy.maxlen == BUSY_LIMIT
        # the running total idle_share reads is the window's sum (kept as runs come and go)
        assert scheduler._busy_total == pytest.approx(sum(d for _, d in busy), abs=1e-9)
    finally:
        scheduler.stop()
    assert len(task.stats.jitter) <= task.stats.jitter.maxlen and len(task.stats.exec_time) <= SAMPLES_KEPT


@given(st.integers(1, 50), st.lists(st.floats(allow_nan=False), max_size=200), st.integers(0, 60))
def test_a_ring_keeps_the_last_samples_in_memory_allocated_up_front(maxlen: int, values: list[float], n: int) -> None:
    ring = Ring(maxlen)
    allocated = ring._values.buffer_info()
    reference: deque[float] = deque(maxlen=maxlen)
    for value in values:
        ring.append(value)
        reference.append(value)
    assert list(ring) == list(reference) and len(ring) == len(reference)
    assert ring.recent(n) == (list(reference)[-n:] if n else [])
    assert ring._values.buffer_info() == allocated  # never grown nor moved


def test_a_node_keeps_a_bounded_number_of_events_and_sends_every_one_to_its_sinks(transport: Transport) -> None:
    system = ckmconf.load(CLOSED_LOOP)
    node = NodeRuntime(system.nodes[0], system, transport)
    seen: list[int] = []
    node.event_sinks.append(lambda event: seen.append(event["n"]))
    for n in range(node_module.EVENTS_KEPT + 500):
        node.report("test", {"n": n})
    assert len(node.events) <= node_module.EVENTS_KEPT
    assert seen == list(range(node_module.EVENTS_KEPT + 500))


def test_the_idle_shares_running_total_follows_runs_dropped_by_the_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """The busy runs' total is kept as they come, leave the window and are pushed out of the bound."""
    monkeypatch.setattr(scheduler_module, "BUSY_LIMIT", 4)
    now = [0.0]
    scheduler = Scheduler("bounded", clock=lambda: now[0])
    durations = [0.1, 0.2, 0.05, 0.3, 0.15, 0.25]

    def run() -> None:
        now[0] += durations[task.stats.releases]

    task = scheduler.add(Task("timed", 0.5, run))
    for _ in durations:
        scheduler._execute(task, now[0])
    assert scheduler.idle_share() == pytest.approx(1.0 - sum(durations[-4:]) / IDLE_WINDOW)
    now[0] += IDLE_WINDOW + 1.0  # every run out of the window
    assert scheduler.idle_share() == 1.0 and scheduler._busy_total == 0.0
