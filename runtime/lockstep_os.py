"""What a lock-step run asks of the operating system: whether a process still runs, and the datagram
socket its wake-ups leave by (issue J point 5, D190; :mod:`runtime.lockstep`)."""

from __future__ import annotations

import os
import socket
from pathlib import Path


def alive(pid: int) -> bool:
    """Whether process ``pid`` still runs (a zombie, ended but not yet reaped by its parent, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat[stat.rfind(")") + 2 :][:1] not in ("Z", "X")


def nonblocking_sender() -> socket.socket:
    """A datagram socket for wake-ups: a send to a full queue fails at once (a wake-up is pending there)."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.setblocking(False)
    return sock
