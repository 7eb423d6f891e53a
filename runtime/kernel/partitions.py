"""Partitions (§3.1.3.2): each partition of a node runs as its own OS process, restarted on its own.

The node's main process runs the unpartitioned components and the monitor; a
``PartitionSupervisor`` starts one ``ckm-run CONFIG --node NODE --partition PART`` process per
partition, watches them from one thread, counts crashes (the monitor's partition-crash alarms read
them), restarts per the partition's policy, and stops them with the node. The partitions of a node
talk over the network transport like any other peers (internal topics get node-local names).

How a partition process is isolated (its parent's death, its memory budget) is described in
:mod:`runtime.kernel.partition_process`, which runs inside each partition process.

CPU: ``cpu`` is advisory. Reserving a share needs cgroups (not writable here) or real-time
scheduling privileges; niceness is a relative weight, and lowering a safety partition's
priority would be the opposite of a reservation. The share is recorded in the statistics
next to the CPU time each partition really used. Best-effort partitions do run at niceness
+10, so under contention they yield to the node's other processes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import psutil

from ckmconf.model import Alarm, Node, Partition

from .. import lockstep
from .partition_process import (
    MEMORY_EXIT,
    PARENT_ENV,
    MemoryWatch,
    enter_partition,
    first_error,
)

LOG = logging.getLogger("ckm.partitions")
CPU_SAMPLE = 1.0  # seconds between CPU-time readings of a running partition
Report = Callable[[str, dict[str, Any]], None]


@dataclass
class Life:
    """One process of a partition, from start to exit."""

    pid: int
    started: float
    ended: float | None = None
    exit_code: int | None = None
    cpu_s: float = 0.0  # user + system CPU time, as last read


@dataclass
class _State:
    record: Partition
    process: subprocess.Popen[bytes] | None = None
    lives: list[Life] = field(default_factory=list)
    crashes: int = 0
    restarts: int = 0
    due: float | None = None  # monotonic time of the next start
    asked: Literal["restart", "stop"] | None = None  # why the supervisor asked the current process to exit
    kill_at: float | None = None  # wall monotonic time after which a process asked to exit is killed
    given_up: bool = False
    sampled: float = 0.0
    console_from: int = 0  # where the current process's output starts in console.log
    first_error: str | None = None  # the first error a crashed process of this partition printed
    verdict: str | None = None  # what a process asked to stop reported failing (its exit code > 0)


class PartitionSupervisor:
    """Starts, watches, restarts and stops the partition processes of one node."""

    def __init__(
        self,
        node: Node,
        config: Path,
        run_dir: Path,
        report: Report,
        *,
        command: Callable[[Partition], list[str]] | None = None,
        poll: float = 0.05,
        stop_timeout: float = 5.0,
    ) -> None:
        """``command`` gives a partition's command line (default: ckm-run of that partition);
        ``poll`` bounds how late an exit or a due restart is noticed; ``stop_timeout`` how long a
        child asked to exit may take before it is killed."""
        self.node = node
        self.config = Path(config).resolve()  # children may run from another directory
        self.run_dir = Path(run_dir).resolve()
        self.report = report
        self.command = command or self._ckm_run
        self.poll = poll
        self.stop_timeout = stop_timeout
        self.states = {p.name: _State(p) for p in node.partitions}
        self._requests: queue.SimpleQueue[tuple[str, bool] | None] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._stopping = False

    def _ckm_run(self, partition: Partition) -> list[str]:
        return [
            sys.executable,
            "-m",
            "runtime.cli",
            str(self.config),
            "--node",
            self.node.name,
            "--partition",
            partition.name,
            "--log-dir",
            str(self.run_dir / partition.name),
        ]

    # ------------------------------------------------------------------ public interface

    def start(self) -> None:
        """Start the supervising thread; every partition is due to start at once (§3.1.3.2)."""
        now = time.monotonic()
        for state in self.states.values():
            state.due = now
        self._thread = threading.Thread(target=self._watch, name=f"ckm-partitions-{self.node.name}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask every partition to stop (SIGTERM), kill those still running after ``stop_timeout``."""
        if self._thread is None:
            return
        self._requests.put(None)
        self._thread.join(4 * self.stop_timeout + 5)  # two groups, each maybe killed
        if self._thread.is_alive():
            LOG.error("%s: partition supervisor did not stop", self.node.name)

    def crashes(self, name: str) -> int:
        """How many times partition ``name`` crashed (for the monitor's partition-crash alarms)."""
        state = self.states.get(name)
        return state.crashes if state is not None else 0

    def pid(self, name: str) -> int | None:
        """The pid of partition ``name``'s running process, if any."""
        process = self.states[name].process
        return process.pid if process is not None else None

    def restart(self, name: str, *, if_down: bool = False) -> None:
        """Restart partition ``name`` now (stopping it first if it runs, unless ``if_down``)."""
        self._requests.put((name, if_down))

    def on_alarm(self, alarm: Alarm) -> None:
        """The alarm action "restart". A crash alarm only wants the partition back: one already
        restarted by its policy is left alone, one waiting out its restartDelay starts now."""
        self.restart(alarm.partition or "", if_down=alarm.measure == "partition-crash")

    def statistics(self) -> dict[str, Any]:
        """Per partition: its kernel.xsd ``Partition`` settings, CPU used, crashes, restarts and last exit."""
        stats: dict[str, Any] = {}
        for name, state in self.states.items():
            record, lives = state.record, list(state.lives)
            alive = sum((life.ended or time.time()) - life.started for life in lives)
            cpu = sum(life.cpu_s for life in lives)
            stats[name] = {
                "criticality": record.criticality,
                "restart": record.restart,
                "max_restarts": record.max_restarts,
                "memory_mib": record.memory,
                "cpu_share": record.cpu,
                "cpu_share_enforced": False,  # advisory: see the module's docstring
                "cpu_seconds": round(cpu, 3),
                "cpu_used": round(cpu / alive, 4) if alive > 0 else 0.0,
                "running": state.process is not None,
                "crashes": state.crashes,
                "restarts": state.restarts,
                "given_up": state.given_up,
                "last_exit_code": lives[-1].exit_code if lives else None,
                "first_error": state.first_error,
                "pids": [dataclasses.asdict(life) for life in lives],
            }
        return stats

    def failures(self) -> list[tuple[str, str]]:
        """(partition, its first error) of every partition that crashed, or that reported a failure
        (a positive exit code) when asked to stop (ckm-run reports them)."""
        crashed = [
            (name, state.first_error or f"crashed {state.crashes} time(s), no error printed")
            for name, state in self.states.items()
            if state.crashes
        ]
        return crashed + [(name, state.verdict) for name, state in self.states.items()
                          if state.verdict is not None and not state.crashes]  # fmt: skip

    # ------------------------------------------------------------------ the watcher thread

    def _watch(self) -> None:
        # This thread forks every child: their PR_SET_PDEATHSIG fires when it ends, so it must
        # outlive them and must never die of an exception.
        while True:
            try:
                request = self._requests.get(timeout=self.poll)
            except queue.Empty:
                request = ("", False)
            if request is None:
                break
            try:
                if request[0]:
                    self._request(*request)
                for state in self.states.values():
                    self._check(state)
            except Exception:
                LOG.exception("%s: partition supervisor", self.node.name)
        self._stop_all()

    def _check(self, state: _State) -> None:
        now = time.monotonic()
        process = state.process
        if process is not None:
            code = process.poll()
            if code is None:
                if state.kill_at is not None and _wall() >= state.kill_at:
                    process.kill()
                    state.kill_at = None
                elif now - state.sampled >= CPU_SAMPLE:
                    state.sampled = now
                    self._sample(state, process.pid)
                return
            self._ended(state, code)
        if state.due is not None and now >= state.due and not self._stopping:
            self._spawn(state)

    def _sample(self, state: _State, pid: int) -> None:
        try:
            times = psutil.Process(pid).cpu_times()
        except psutil.Error:
            return
        state.lives[-1].cpu_s = times.user + times.system

    def _spawn(self, state: _State) -> None:
        record = state.record
        state.due = None
        restart = bool(state.lives)
        if restart:
            state.restarts += 1
        folder = self.run_dir / record.name
        folder.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, PARENT_ENV: str(os.getpid())}
        try:
            with (folder / "console.log").open("ab") as console:
                state.console_from = console.tell()
                # A session of its own: a terminal's Ctrl-C reaches the supervisor only, which
                # then stops the children itself (else an "always" child could be restarted).
                process = subprocess.Popen(
                    self.command(record),
                    stdin=subprocess.DEVNULL,
                    stdout=console,
                    stderr=subprocess.STDOUT,
                    env=env,
                    start_new_session=True,
                )
        except OSError as exc:
            state.crashes += 1
            self.report("partition-crashed", {"partition": record.name, "pid": None, "error": str(exc)})
            self._after_exit(state, crashed=True)
            return
        state.process = process
        state.given_up = False
        state.sampled = time.monotonic()
        state.lives.append(Life(process.pid, time.time()))
        if restart:
            detail = {"partition": record.name, "pid": process.pid, "restarts": state.restarts}
            self.report("partition-restarted", detail)
        else:
            self.report("partition-started", {"partition": record.name, "pid": process.pid})

    def _ended(self, state: _State, code: int) -> None:
        life = state.lives[-1]
        life.ended, life.exit_code = time.time(), code
        asked, state.asked = state.asked, None
        state.process, state.kill_at = None, None
        if asked is not None:  # an exit the supervisor asked for is never a crash ...
            if code > 0:  # ... but its own verdict may say something failed while it ran (issue G)
                error = first_error(self.run_dir / state.record.name / "console.log", state.console_from)
                state.verdict = state.verdict or error or f"exited with code {code} when stopped"
            if asked == "restart" and not self._stopping:
                state.due = time.monotonic()
            return
        detail: dict[str, Any] = {"partition": state.record.name, "pid": life.pid, "exit_code": code}
        if code == MEMORY_EXIT:
            detail["reason"] = "memory budget exceeded"
        if code < 0:
            with contextlib.suppress(ValueError):
                detail["signal"] = signal.Signals(-code).name
        crashed = code != 0
        if crashed:
            state.crashes += 1
            error = first_error(self.run_dir / state.record.name / "console.log", state.console_from)
            if error is not None:
                detail["error"] = error
                state.first_error = state.first_error or error
        self.report("partition-crashed" if crashed else "partition-exited", detail)
        self._after_exit(state, crashed=crashed)

    def _after_exit(self, state: _State, *, crashed: bool) -> None:
        record = state.record
        if record.restart == "always" or (record.restart == "on-failure" and crashed):
            if state.restarts < record.max_restarts:
                state.due = time.monotonic() + record.restart_delay
                return
            reason = f"maxRestarts ({record.max_restarts}) reached"
        elif crashed:
            reason = 'restart="never"'
        else:
            return  # a clean exit under on-failure or never: the partition just stays stopped
        state.given_up = True
        self.report("partition-given-up", {"partition": record.name, "reason": reason, "crashes": state.crashes})

    def _request(self, name: str, if_down: bool) -> None:
        state = self.states.get(name)
        if state is None or self._stopping:
            self.report("reaction-unavailable", {"action": "restart", "partition": name})
            return
        running = state.process is not None
        if (running and if_down) or state.asked == "restart":
            return  # already back up, or already on its way to a restart
        if state.due is not None:  # waiting out its restartDelay: now
            state.due = time.monotonic()
            return
        if state.restarts >= state.record.max_restarts:
            reason = f"maxRestarts ({state.record.max_restarts}) reached"
            self.report("reaction-unavailable", {"action": "restart", "partition": name, "reason": reason})
            return
        if state.process is not None:
            state.asked, state.kill_at = "restart", _wall() + self.stop_timeout
            state.process.terminate()
        else:
            state.due = time.monotonic()

    def _stop_all(self) -> None:
        self._stopping = True
        # Command sources first: a partition that drives no actuator is gone before the ones that
        # do go safe, so no late command reaches an actuator after its safe value.
        driving = {a.partition for a in self.node.actuators}
        states = list(self.states.values())
        self._stop_group([s for s in states if s.record.name not in driving])
        self._stop_group([s for s in states if s.record.name in driving])

    def _stop_group(self, states: list[_State]) -> None:
        running = [s for s in states if s.process is not None]
        for state in running:
            assert state.process is not None
            self._sample(state, state.process.pid)  # its last CPU reading
            state.asked = "stop"
            state.process.terminate()
        deadline = _wall() + self.stop_timeout
        for state in running:
            assert state.process is not None
            try:
                code = state.process.wait(max(0.0, deadline - _wall()))
            except subprocess.TimeoutExpired:
                LOG.warning("%s: partition %s ignored SIGTERM; killing it", self.node.name, state.record.name)
                state.process.kill()
                try:
                    code = state.process.wait(self.stop_timeout)
                except subprocess.TimeoutExpired:  # unkillable (stuck in the kernel): nothing more to do
                    LOG.error("%s: partition %s survived SIGKILL", self.node.name, state.record.name)
                    continue
            self._ended(state, code)


def _wall() -> float:
    """The wall clock: a stop's bound is on it, not on a lock-step or scaled clock, which may run
    far ahead of the wall while the supervisor waits (a partition killed while stopping cleanly)."""
    return float(lockstep.real("monotonic")())


__all__ = ["MEMORY_EXIT", "Life", "MemoryWatch", "PartitionSupervisor", "enter_partition", "first_error"]
