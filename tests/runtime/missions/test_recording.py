"""RunRecorder and read_run: the line format, crash tolerance, merging agents, thread safety."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from runtime.missions.recording import RunError, RunRecorder, agent_file_name, read_run

REPO = Path(__file__).resolve().parents[3]


class FakeClock:
    """A monotonic clock the test moves by hand."""

    def __init__(self, now: float = 1000.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def lines(path: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_each_event_is_one_line_with_t_agent_kind(tmp_path: Path) -> None:
    clock = FakeClock()
    with RunRecorder(tmp_path, "Agent1", clock=clock, wall_clock=lambda: 5000.0) as recorder:
        recorder.write("start", mission="Fetch", plan=None)
        clock.now += 1.25
        recorder.write("enter", path="Fetch/NAV", state="NAV", mission="Fetch", behavior="Nav", nested=None)
        clock.now += 0.5
        recorder.write("end", outcome="done", wall=5001.75)
    written = lines(tmp_path / "mission-Agent1.jsonl")
    for event in (written[0], written[-1]):  # start and end: the machine's own clock too (D248)
        real = event.pop("real")
        assert isinstance(real, float) and abs(real - time.clock_gettime(time.CLOCK_REALTIME)) < 600
    assert written == [
        {"t": 0.0, "agent": "Agent1", "kind": "start", "mission": "Fetch", "plan": None, "wall": 5000.0},
        {
            "t": 1.25,
            "agent": "Agent1",
            "kind": "enter",
            "path": "Fetch/NAV",
            "state": "NAV",
            "mission": "Fetch",
            "behavior": "Nav",
            "nested": None,
        },
        {"t": 1.75, "agent": "Agent1", "kind": "end", "outcome": "done", "wall": 5001.75},
    ]


def test_no_file_until_the_first_write_and_nan_is_null(tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path / "run", "A", clock=FakeClock())
    assert not (tmp_path / "run").exists()
    recorder.write("progress", path="M/S", progress=float("nan"), performance=float("inf"), mission_progress=0.5)
    recorder.close()
    recorder.close()  # idempotent
    (event,) = lines(tmp_path / "run" / "mission-A.jsonl")
    assert event["progress"] is None and event["performance"] is None


def test_unknown_kind_is_an_error_and_a_write_after_close_is_dropped(tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path, "A", clock=FakeClock())
    with pytest.raises(ValueError, match="bad event kind 'Enter!'"):
        recorder.write("Enter!")
    assert recorder.write("agent-found", found="B")  # kinds beyond the known ones are recorded too
    recorder.close()
    assert recorder.write("end", outcome="x") is False  # a late writer is not crashed
    assert recorder.dropped == 1
    lines = (tmp_path / "mission-A.jsonl").read_text().splitlines()
    assert [json.loads(line)["kind"] for line in lines] == ["agent-found"]


def test_close_under_concurrent_writers_loses_no_accepted_line(tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path, "A", fsync_every=10.0)
    accepted = [0] * 4

    def writer(index: int) -> None:
        for n in range(2000):
            if recorder.write("log", writer=index, n=n):
                accepted[index] += 1

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(4)]
    for thread in threads:
        thread.start()
    time.sleep(0.01)
    recorder.close()
    for thread in threads:
        thread.join(10)
    lines = (tmp_path / "mission-A.jsonl").read_text().splitlines()
    assert len(lines) == sum(accepted)
    assert all(json.loads(line)["kind"] == "log" for line in lines)  # every line whole
    assert recorder.dropped == 4 * 2000 - sum(accepted)


@pytest.mark.parametrize(
    ("agent", "name"),
    [("Agent1", "mission-Agent1.jsonl"), ("Nao robot/2", "mission-Nao_robot_2.jsonl"), ("..", "mission-agent.jsonl")],
)
def test_agent_file_names_are_safe(agent: str, name: str) -> None:
    assert agent_file_name(agent) == name


def write_run(run_dir: Path, agent: str, count: int) -> Path:
    clock = FakeClock()
    with RunRecorder(run_dir, agent, clock=clock) as recorder:
        recorder.write("start", mission="M", plan=None, wall=100.0)
        for i in range(1, count):
            clock.now += 1.0
            recorder.write("progress", path="M/S", progress=i / count, performance=0.9, mission_progress=i / count)
    return recorder.path


def test_a_half_written_last_line_is_skipped_with_a_note(tmp_path: Path) -> None:
    path = write_run(tmp_path, "A", 5)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 20])  # cut the fifth line in the middle
    run = read_run(tmp_path)
    assert [e.local_t for e in run.events] == [0.0, 1.0, 2.0, 3.0]
    assert run.notes == ["mission-A.jsonl:5: skipped: half-written last line (the writer stopped mid-line)"]


def test_a_recorder_reopening_a_crashed_file_starts_a_fresh_line(tmp_path: Path) -> None:
    path = write_run(tmp_path, "A", 3)
    path.write_bytes(path.read_bytes()[:-10])
    with RunRecorder(tmp_path, "A", clock=FakeClock()) as recorder:
        recorder.write("start", mission="M", plan=None, wall=200.0)
    run = read_run(tmp_path)
    assert [(e.kind, e.t) for e in run.events] == [("start", 0.0), ("progress", 1.0), ("start", 100.0)]
    assert run.notes == ["mission-A.jsonl:3: skipped: not valid JSON"]


def test_bad_lines_are_skipped_with_their_file_and_line(tmp_path: Path) -> None:
    (tmp_path / "mission-A.jsonl").write_text(
        '{"t":0,"agent":"A","kind":"start","mission":"M","wall":1}\n'
        "[1, 2]\n"
        '{"t":"x","agent":"A","kind":"end"}\n'
        '{"t":1,"agent":"A","kind":"Dance!"}\n'
        '{"t":1.5,"agent":"A","kind":"dance"}\n'
        "\n"
        '{"t":2,"agent":"A","kind":"end","outcome":"ok","wall":3}\n'
    )
    run = read_run(tmp_path)
    assert [e.kind for e in run.events] == ["start", "dance", "end"]
    assert run.notes == [
        "mission-A.jsonl:2: skipped: not a JSON object",
        "mission-A.jsonl:3: skipped: no numeric 't'",
        "mission-A.jsonl:4: skipped: bad kind 'Dance!'",
    ]
    assert run.agents["A"].outcome == "ok" and run.agents["A"].duration == 2.0


def test_a_killed_writer_leaves_every_complete_line_readable(tmp_path: Path) -> None:
    script = textwrap.dedent(
        """
        import sys, time
        from pathlib import Path
        from runtime.missions.recording import RunRecorder
        recorder = RunRecorder(Path(sys.argv[1]), "Writer", fsync_every=0.05)
        recorder.write("start", mission="M", plan=None)
        print("ready", flush=True)
        i = 0
        while True:
            i += 1
            recorder.write("quality", service="R.S", client="c", measures={"m" + str(k): k * i for k in range(200)},
                           scenario="x" * (i % 5000))
        """
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], stdout=subprocess.PIPE, env=env, cwd=REPO)
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == b"ready"
        time.sleep(0.3)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=10)
    raw = (tmp_path / "mission-Writer.jsonl").read_bytes()
    complete = raw.count(b"\n")
    assert complete > 10
    run = read_run(tmp_path)
    assert len(run.events) == complete
    assert run.events[0].kind == "start"
    assert all(e.kind == "quality" for e in run.events[1:])
    if not raw.endswith(b"\n"):
        assert run.notes == [
            f"mission-Writer.jsonl:{complete + 1}: skipped: half-written last line (the writer stopped mid-line)"
        ]
    else:
        assert run.notes == []


def test_agents_files_are_merged_on_their_wall_anchors(tmp_path: Path) -> None:
    a_clock, b_clock = FakeClock(10.0), FakeClock(777.0)
    a = RunRecorder(tmp_path, "A", clock=a_clock)
    b = RunRecorder(tmp_path, "B", clock=b_clock)
    b_clock.now += 0.5
    b.write("start", mission="MB", plan="P", wall=1003.0)  # t = 0.5: B's t = 0 was wall 1002.5
    a.write("start", mission="MA", plan="P", wall=1000.0)
    a_clock.now += 3.5
    a.write("signal", name="go", direction="sent", value=1)
    b_clock.now += 1.0
    b.write("signal", name="go", direction="received", value=1)  # t = 1.5 → 4.0
    a_clock.now += 1.5
    a.write("end", outcome="done", wall=1005.0)
    b_clock.now += 2.0
    b.write("end", outcome="done", wall=1006.0)
    a.close()
    b.close()
    run = read_run(tmp_path)
    assert [(e.agent, e.kind, e.t) for e in run.events] == [
        ("A", "start", 0.0),
        ("B", "start", 3.0),
        ("A", "signal", 3.5),
        ("B", "signal", 4.0),
        ("A", "end", 5.0),
        ("B", "end", 6.0),
    ]
    assert list(run.agents) == ["A", "B"]
    assert (run.agents["B"].start, run.agents["B"].end, run.agents["B"].mission) == (3.0, 6.0, "MB")
    assert run.notes == []


def test_the_recorder_is_thread_safe(tmp_path: Path) -> None:
    recorder = RunRecorder(tmp_path, "A", fsync_every=0.01)
    recorder.write("start", mission="M", plan=None)

    def work(n: int) -> None:
        for i in range(200):
            recorder.write("signal", name=f"s{n}", direction="sent", value={"i": i, "pad": "x" * (i * 20)})

    threads = [threading.Thread(target=work, args=(n,)) for n in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=10)
    recorder.close()
    events = lines(recorder.path)
    assert len(events) == 1 + 8 * 200
    for n in range(8):
        assert [e["value"]["i"] for e in events if e.get("name") == f"s{n}"] == list(range(200))  # type: ignore[index]
    times = [e["t"] for e in events]
    assert times == sorted(times)  # type: ignore[type-var]


def test_unreadable_run_directories_raise_run_error(tmp_path: Path) -> None:
    with pytest.raises(RunError, match="no such run directory"):
        read_run(tmp_path / "missing")
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunError, match="not a directory"):
        read_run(tmp_path / "file")
    with pytest.raises(RunError, match=r"no mission recording \(mission\*\.jsonl\)"):
        read_run(tmp_path)
    (tmp_path / "mission-A.jsonl").write_text("")
    with pytest.raises(RunError, match=r"no readable events in mission-A\.jsonl"):
        read_run(tmp_path)
