"""What the lock-step clock needs of the operating system (D190, D233): whether a process still runs,
wake-up datagrams that never spin, and marking the clock's own threads."""

from __future__ import annotations

import os
import socket
import struct
import threading
from pathlib import Path


def sender(timeout: float) -> socket.socket:
    """A datagram socket whose sends to a full queue sleep in the kernel for at most ``timeout`` s (D233).

    A Python-level timeout (``settimeout``) polls for writability first, and an unconnected AF_UNIX
    datagram socket is always writable: while the receiver's queue (``net.unix.max_dgram_qlen``, 10)
    was full, its ``sendto`` spun (34 s of system time in a 20 s run). A blocking socket with a kernel
    send timeout sleeps until the receiver reads; past the timeout the datagram is dropped (OSError).
    """
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    whole = int(timeout)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, struct.pack("ll", whole, int((timeout - whole) * 1e6)))
    return sock


def drain(sock: socket.socket, timeout: float) -> None:
    """Read every datagram already queued on ``sock`` (a wake-up says only "look"), then wait with ``timeout`` again."""
    sock.setblocking(False)
    try:
        while True:
            sock.recv(16)
    except OSError:
        pass
    finally:
        sock.settimeout(timeout)


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


def unheld(thread: threading.Thread) -> threading.Thread:
    """``thread`` does not hold the clock as a newborn when started (the clock's own threads: D220)."""
    thread.ckm_unheld = True  # type: ignore[attr-defined]
    return thread
