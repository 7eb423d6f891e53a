"""Starting, watching and stopping the world server around a run (issue J point 5, D102).

:func:`world_session` is what ``hardware.sim``'s ``run_session`` hook gives ``ckm-run``
(``runtime.sessions``): when the nodes run by this ``ckm-run`` have a sim channel and no server is
named already (``CKM_SIM_SERVER`` unset), it plans the world (a wrong or conflicting Param is a
located ConfigError: exit 1), starts ``python -m plugins.sim.server`` with a fresh key, waits until
it listens, and puts its address and key in this process's environment, so every channel built
afterwards — here and in the partition processes, which inherit it — is its client. A thread
watches the server: if it exits while the run lasts, ``failed`` is called with the reason (ckm-run
stops the run and exits 5). At the end the server is stopped (SIGTERM, then SIGKILL) and the
variables removed. Its log is RUN_DIR/sim-server.log, its address and pid RUN_DIR/sim-server.json
(sim-server-NODE.log/json for a ``--node NODE`` run, as several may share a run directory).
"""

from __future__ import annotations

import json
import logging
import os
import secrets
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from ckmconf.model import Node, System
from runtime import lockstep

from .client import ENV_ADDRESS, ENV_KEY, Address
from .plan import WorldPlan

LOG = logging.getLogger("ckm.sim.session")
START_TIMEOUT = 120.0  # seconds to build the world (the lab with textures: ~2 s quiet, far more loaded)
STOP_TIMEOUT = 5.0
STEM = "sim-server"
READY = f"{STEM}.json"  # the files of a run of every node; a --node run's carry its nodes' names (D64)
LOGFILE = f"{STEM}.log"


class ServerProcess:
    """A world server child process (also used by the tests and ``benchmarks.sim_server``)."""

    def __init__(
        self, config: Path, run_dir: Path, nodes: Sequence[str] = (), timeout: float = START_TIMEOUT,
        options: Sequence[str] = (), stem: str = STEM,
    ) -> None:
        """``options``: more command-line options of the server (``--render-workers N``); ``stem``
        names its files in ``run_dir`` (STEM.json, STEM.log)."""
        run_dir.mkdir(parents=True, exist_ok=True)
        self.key = secrets.token_bytes(32)
        self.ready = run_dir / f"{stem}.json"
        self.log = run_dir / f"{stem}.log"
        self.ready.unlink(missing_ok=True)
        command = [sys.executable, "-m", "plugins.sim.server", str(Path(config).resolve()),
                   "--ready", str(self.ready), "--parent", str(os.getpid())]
        for node in nodes:
            command += ["--node", node]
        command += list(options)
        env = {**os.environ, ENV_KEY: self.key.hex()}
        env.pop(ENV_ADDRESS, None)
        with self.log.open("ab") as log:
            # A session of its own: a terminal's Ctrl-C reaches ckm-run, which stops the server last.
            self.process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                            env=env, start_new_session=True)
        self.address = self._await_ready(timeout)

    def _await_ready(self, timeout: float) -> str:
        # the wall clock: building the world takes what it takes, and in lock-step the run's clock
        # stands still meanwhile (the main thread holds it: D190)
        monotonic, sleep = lockstep.real("monotonic"), lockstep.real("sleep")
        deadline = monotonic() + timeout
        while monotonic() < deadline:
            if self.ready.is_file():
                return str(json.loads(self.ready.read_text())["address"])
            if self.process.poll() is not None:
                raise RuntimeError(f"the simulated world server could not start (exit {self.process.returncode}): "
                                   f"{self.last_line()}")
            sleep(0.05)
        self.stop()
        raise RuntimeError(f"the simulated world server did not listen within {timeout:g} s (log: {self.log})")

    @property
    def pid(self) -> int:
        """The world server process's id."""
        return self.process.pid

    def client_address(self) -> Address:
        """The address clients connect to (``CKM_SIM_SERVER``)."""
        host, _, port = self.address.rpartition(":")
        return host, int(port), self.key

    def environ(self) -> dict[str, str]:
        """The variables that make a process's sim channels clients of this server."""
        return {ENV_ADDRESS: self.address, ENV_KEY: self.key.hex()}

    def last_line(self) -> str:
        """The server's last log line (its error, when it failed)."""
        try:
            lines = [line for line in self.log.read_text(errors="replace").splitlines() if line.strip()]
        except OSError:
            return "(no log)"
        return lines[-1].strip() if lines else "(nothing logged)"

    def stop(self) -> int | None:
        """Stop the server (SIGTERM, SIGKILL after STOP_TIMEOUT); its exit code."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                LOG.warning("world server %d ignored SIGTERM: killing it", self.pid)
                self.process.kill()
                self.process.wait(STOP_TIMEOUT)
        return self.process.returncode

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, tb: TracebackType | None) -> None:
        self.stop()


def _watch(server: ServerProcess, ending: threading.Event, failed: Callable[[str], None]) -> None:
    while not ending.wait(0.1):
        code = server.process.poll()
        if code is not None and not ending.is_set():
            how = f"was killed by signal {-code}" if code < 0 else f"exited with code {code} ({server.last_line()})"
            failed(f"the simulated world server (pid {server.pid}) {how} while the run lasted; stopping the run "
                   f"(its log: {server.log})")
            return


@contextmanager
def world_session(
    system: System, config: Path, run_dir: Path, nodes: Sequence[Node], failed: Callable[[str], None]
) -> Iterator[None]:
    """The run's world server while the block lasts (see the module docstring)."""
    if os.environ.get(ENV_ADDRESS) or WorldPlan.of(list(nodes)) is None:
        yield  # a server named already (or "off"), or no sim channel here: nothing to start
        return
    names = [n.name for n in nodes]
    every = names == [n.name for n in system.nodes]
    # several `ckm-run --node` processes may share a run directory (D64): each its own files
    server = ServerProcess(config, run_dir, names, stem=STEM if every else "-".join([STEM, *names]))
    LOG.info("world server %d listening on %s (log %s)", server.pid, server.address, server.log)
    ending = threading.Event()
    watcher = threading.Thread(target=_watch, args=(server, ending, failed), name="ckm-sim-watch", daemon=True)
    os.environ.update(server.environ())
    watcher.start()
    try:
        yield
    finally:
        ending.set()
        watcher.join(1.0)
        for name in (ENV_ADDRESS, ENV_KEY):
            os.environ.pop(name, None)
        code = server.stop()
        LOG.info("world server %d stopped (exit %s)", server.pid, code)
