"""The client side of the world server (issue J point 5, decisions D100–D101).

A ``hardware.sim`` channel is a client when its process's environment names the run's server:
``CKM_SIM_SERVER`` = ``127.0.0.1:PORT`` and ``CKM_SIM_AUTHKEY`` = the key in hex (``ckm-run`` sets
both before it builds nodes or starts partitions, which inherit them). ``CKM_SIM_SERVER=off`` keeps
every world in-process even under ``ckm-run``.

Each channel holds its own connection (``multiprocessing.connection``, HMAC-authenticated): a
request is a JSON object (``send_bytes``), so a malformed one can be answered with an error; a
reply is a pickled dict (``recv``), arrays whole. An error reply raises here the exception type the
server met (KeyError for an unknown joint, ParamError, ValueError), with its message naming the
channel; a lost server raises ConnectionError; a server that does not answer within ``TIMEOUT``
raises TimeoutError.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
from multiprocessing.connection import Client, Connection
from typing import Any

from runtime import lockstep
from runtime.kernel.interfaces import ParamError

from .devices import Sample, Spec

ENV_ADDRESS = "CKM_SIM_SERVER"
ENV_KEY = "CKM_SIM_AUTHKEY"
OFF = "off"
TIMEOUT = 30.0
"""Seconds a request may wait for its reply (a VGA render on a loaded machine takes ~0.15 s)."""

Address = tuple[str, int, bytes]
_ERRORS: dict[str, type[Exception]] = {
    "KeyError": KeyError, "ParamError": ParamError, "ValueError": ValueError, "TypeError": ValueError,
    "FileNotFoundError": FileNotFoundError, "JSONDecodeError": ValueError, "UnicodeDecodeError": ValueError,
}


def no_delay(conn: Connection) -> None:
    """Send each message at once (TCP_NODELAY): a request or reply is one write, and Nagle's wait
    for an acknowledgement made a wheel read's round trip 0.4 ms instead of 0.03 ms (measured)."""
    with contextlib.suppress(OSError):
        sock = socket.socket(fileno=os.dup(conn.fileno()))  # the same socket, through a duplicate
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.close()


class ServerError(RuntimeError):
    """An error the world server reported that has no closer Python type."""


def server_address(environ: dict[str, str] | None = None) -> Address | None:
    """(host, port, authkey) of the run's world server, or None for in-process worlds."""
    env = os.environ if environ is None else environ
    text = env.get(ENV_ADDRESS, "").strip()
    if not text or text == OFF:
        return None
    host, _, port = text.rpartition(":")
    try:
        key = bytes.fromhex(env.get(ENV_KEY, ""))
        number = int(port)
    except ValueError:
        raise ValueError(f"{ENV_ADDRESS}={text!r} / {ENV_KEY}: expected HOST:PORT and a hex key") from None
    if not host or not key:
        raise ValueError(f"{ENV_ADDRESS}={text!r} / {ENV_KEY}: expected HOST:PORT and a hex key")
    return host, number, key


class Link:
    """One authenticated connection to the world server; requests are serialised per link."""

    def __init__(self, address: Address, owner: str = "world server client", timeout: float = TIMEOUT) -> None:
        self.address, self.owner, self.timeout = address, owner, timeout
        self._lock = threading.Lock()
        host, port, key = address
        try:
            self._conn: Connection | None = Client((host, port), authkey=key)
        except (OSError, EOFError) as exc:
            raise ConnectionError(f"{owner}: cannot reach the world server at {host}:{port}: {exc}") from None
        no_delay(self._conn)

    def request(self, message: dict[str, Any], *, answer: bool = True) -> dict[str, Any]:
        """Send ``message``, return the reply; raise what an error reply says. ``answer=False``: a
        silent write (``"reply": false``), whose error, if any, is raised by the next exchange."""
        return self.exchange(json.dumps(message).encode(), answer=answer)

    def exchange(self, data: bytes, *, answer: bool = True) -> dict[str, Any]:
        """Send raw request bytes (tests send malformed ones), return the reply or raise its error."""
        host, port, _ = self.address
        with self._lock:
            if self._conn is None:
                raise ConnectionError(f"{self.owner}: the link to the world server is closed")
            try:
                late = self._late(self._conn)  # a silent write's error already here
                self._conn.send_bytes(data)
                reply: Any = {}
                while answer:
                    if not self._conn.poll(self.timeout):
                        raise TimeoutError(f"{self.owner}: the world server at {host}:{port} did not answer "
                                           f"within {self.timeout:g} s")
                    reply = self._conn.recv()
                    if not (isinstance(reply, dict) and reply.get("silent")):
                        break
                    late = late or reply  # an earlier silent write's error, arrived meanwhile
            except (EOFError, OSError) as exc:
                if isinstance(exc, TimeoutError):
                    raise
                raise ConnectionError(f"{self.owner}: the world server at {host}:{port} is gone "
                                      f"({type(exc).__name__}: {exc})") from None
        for got in (late, reply):
            if not isinstance(got, dict):
                raise ServerError(f"{self.owner}: the world server answered {type(got).__name__}, not a reply")
            if "error" in got:
                raise _ERRORS.get(str(got.get("type")), ServerError)(str(got["error"]))
        return dict(reply)

    @staticmethod
    def _late(conn: Connection) -> dict[str, Any]:
        """The first error reply waiting unread (only silent writes' errors can be)."""
        late: dict[str, Any] = {}
        while conn.poll(0):
            got = conn.recv()
            if isinstance(got, dict) and "error" in got and not late:
                late = got
        return late

    def close(self) -> None:
        """Close the connection to the world server (idempotent)."""
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None


class RemoteDevice:
    """A channel's device held by the world server (the client half of :class:`ChannelDevice`)."""

    def __init__(self, address: Address, spec: Spec) -> None:
        self.link = Link(address, f"sim channel {spec.name!r}")
        try:
            self.handle = int(self.link.request({"op": "open", "spec": spec.to_dict()})["handle"])
        except BaseException:
            self.link.close()
            raise

    def read(self) -> Sample:
        """The device's value now, read in the world server."""
        value: Sample = self.link.request({"op": "read", "handle": self.handle})["value"]
        return value

    def order(self) -> int:
        """Order a camera's frame of the world now, rendered while the world runs on; its ticket (D246)."""
        return int(self.link.request({"op": "render", "handle": self.handle})["ticket"])

    def collect(self, ticket: int) -> Sample:
        """The frame ordered with ``ticket``, waiting for it if it is not made yet."""
        value: Sample = self.link.request({"op": "frame", "handle": self.handle, "ticket": ticket})["value"]
        return value

    def write(self, raw: float | list[float]) -> None:
        """Write ``raw`` (a multirotor's set-point: a list) to the device in the world server (no reply
        unless it fails)."""
        # silent: an actuator's write waits for no round trip (its error comes with the next one); in
        # lock-step answered, so it is applied before the run's clock moves on (D190)
        answered = lockstep.active() is not None
        self.link.request({"op": "write", "handle": self.handle, "value": raw, "reply": answered}, answer=answered)

    def close(self) -> None:
        """Release the channel in the world server and drop the link."""
        # closing: a server already gone has nothing to release
        with contextlib.suppress(ConnectionError, TimeoutError, ServerError, ValueError):
            self.link.request({"op": "close", "handle": self.handle})
        self.link.close()
