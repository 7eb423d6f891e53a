"""The HFSM engine (§5.2) on simulated time: nested missions in order and their outcomes, an
untraceable behavior bounded by its timeout, an outer timeout pre-empting a nested mission,
mission progress, signals, and the recording of it all."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.missions.hfsm import MissionEngine, MissionError, distances_to_success
from runtime.missions.recording import RunRecorder, read_run
from runtime.missions.signals import Signals
from runtime.registry import default_registry

DATA = Path(__file__).resolve().parents[2] / "data" / "missions"


class Clock:
    def __init__(self) -> None:
        self.time = 0.0

    def __call__(self) -> float:
        return self.time


def factory(
    system: System, inputs: dict[str, Any] | None = None
) -> Callable[[str, str, Callable[[], float]], Behavior]:
    registry = default_registry()
    values = inputs or {}

    def make(behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        record = system.behavior(behavior)
        assert record is not None
        readers = {p.name: (lambda name=p.name: values.get(name)) for p in record.inputs}
        context = BehaviorContext(services={}, inputs=readers, outputs={}, now=now)
        instance: Behavior = registry.resolve("behavior", record.kind, record)(record, context)
        return instance

    return make


def run(engine: MissionEngine, clock: Clock, until: float = 60.0, step: float = 0.1) -> list[str]:
    paths: list[str] = []
    engine.start()
    while engine.outcome is None and clock.time < until:
        clock.time += step
        engine.step()
        path = engine.active_path()
        if path is not None and (not paths or paths[-1] != path):
            paths.append(path)
    return paths


@pytest.fixture(scope="module")
def system() -> System:
    return ckmconf.load(DATA / "nested_timers.xml")


def test_nested_missions_run_in_order_and_end_in_their_outcomes(system: System, tmp_path: Path) -> None:
    clock = Clock()
    with RunRecorder(tmp_path, "robot", clock=clock) as recorder:
        engine = MissionEngine(system, "Top", factory=factory(system), clock=clock, recorder=recorder)
        paths = run(engine, clock)
    assert engine.outcome == "success"
    assert paths == ["Top/FIRST/A", "Top/FIRST/B", "Top/SECOND/WAIT", "Top/THIRD/L"]
    events = read_run(tmp_path).events
    outcomes = [(e.fields["mission"], e.fields["outcome"]) for e in events if e.kind == "outcome"]
    assert outcomes == [("Inner", "ok"), ("Stuck", "timed_out"), ("Top", "success")]
    entered = {e.fields["path"]: e.t for e in events if e.kind == "enter"}
    # A takes 1 s, B 2 s, the untraceable WAIT its 3 s timeout, THIRD is cut by its 5 s timeout.
    assert entered["Top/FIRST/B"] == pytest.approx(1.1, abs=0.15)
    assert entered["Top/SECOND/WAIT"] == pytest.approx(3.2, abs=0.25)
    assert entered["Top/THIRD/L"] == pytest.approx(6.3, abs=0.35)
    exits = [e for e in events if e.kind == "exit" and e.fields["state"] == "L"]
    assert exits[0].fields["reason"] == "stopped"  # pre-empted by THIRD's timeout, not finished
    end = next(e for e in events if e.kind == "end")
    assert end.fields["outcome"] == "success" and end.t == pytest.approx(11.4, abs=0.5)


def test_a_stuck_untraceable_behavior_times_out(system: System) -> None:
    clock = Clock()
    engine = MissionEngine(system, "Stuck", factory=factory(system), clock=clock)
    run(engine, clock)
    assert engine.outcome == "timed_out" and clock.time == pytest.approx(3.1, abs=0.15)
    clock = Clock()
    engine = MissionEngine(system, "Stuck", factory=factory(system, {"never": "here"}), clock=clock)
    run(engine, clock)
    assert engine.outcome == "got" and clock.time < 0.5


def test_mission_progress_grows_to_one_along_the_success_path(system: System, tmp_path: Path) -> None:
    clock = Clock()
    with RunRecorder(tmp_path, "robot", clock=clock) as recorder:
        engine = MissionEngine(system, "Inner", factory=factory(system), clock=clock, recorder=recorder)
        run(engine, clock)
    progress = [e.fields["mission_progress"] for e in read_run(tmp_path).events if e.kind == "progress"]
    assert progress == sorted(progress) and progress[-1] == 1.0 and progress[0] < 0.2
    assert distances_to_success(system.mission("Inner")) == {"ok": 0, "B": 1, "A": 2}  # type: ignore[arg-type]


def test_signals_are_emitted_on_entry_done_and_exit(system: System) -> None:
    clock, sent = Clock(), []
    signals = Signals()
    engine = MissionEngine(
        system, "Inner", factory=factory(system), clock=clock, signals=signals,
        emitters={("B", "entry"): "b-started", ("A", "done"): "a-done"},
        on_signal=lambda name, value: sent.append(name),
    )  # fmt: skip
    run(engine, clock)
    assert sent == ["a-done", "b-started"] and signals.received("a-done")


def test_unknown_missions_and_behaviors_are_clear_errors(system: System) -> None:
    with pytest.raises(MissionError, match="no mission 'Nope'"):
        MissionEngine(system, "Nope", factory=factory(system), clock=Clock())


FAILING = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="failing">
  <Behavior name="PLACE" kind="timer"/>
  <Mission name="Place" initial="PLACE">
    <State name="PLACE" behavior="PLACE"/>
    <Final name="placed"/>
    <Final name="failed"/>
    <Transition from="PLACE" to="placed" when="done()"/>
    <Transition from="PLACE" to="failed" when="failed()"/>
  </Mission>
</System>
"""


def test_a_failed_behaviors_detail_is_recorded_with_its_exit(tmp_path: Path) -> None:
    (tmp_path / "failing.xml").write_text(FAILING)
    system = ckmconf.load(tmp_path / "failing.xml")

    class Blocked(Behavior):
        def step(self) -> BehaviorStatus:
            return BehaviorStatus(failed=True, detail="arm:place: goal 3: arm pose 'place' not reached")

    def make(behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        record = system.behavior(behavior)
        assert record is not None
        return Blocked(record, BehaviorContext(services={}, inputs={}, outputs={}, now=now))

    clock = Clock()
    with RunRecorder(tmp_path / "run", "robot", clock=clock) as recorder:
        engine = MissionEngine(system, "Place", factory=make, clock=clock, recorder=recorder)
        run(engine, clock)
    assert engine.outcome == "failed"
    [exit_] = [e for e in read_run(tmp_path / "run").events if e.kind == "exit"]
    assert exit_.fields["detail"] == "arm:place: goal 3: arm pose 'place' not reached"
    assert engine.failures == ["Place/PLACE: arm:place: goal 3: arm pose 'place' not reached"]  # for the terminal


def test_the_terminal_names_the_state_that_failed_a_mission(capsys: pytest.CaptureFixture[str]) -> None:
    from types import SimpleNamespace

    from runtime.cli import EXIT_AGENTS, _verdict

    runner = SimpleNamespace(succeeded=False, engine=SimpleNamespace(failures=["Place/PLACE: arm:place: blocked"]))
    agent = SimpleNamespace(name="turtlebot", outcome="failed", error=None, runner=runner)
    assert _verdict([], [agent]) == EXIT_AGENTS  # type: ignore[list-item]
    assert "agent turtlebot: mission ended failed (last failed state: Place/PLACE: arm:place: blocked)" in (
        capsys.readouterr().err
    )
