"""One TCP connection between two peers (§3.1.4.1): handshake, authenticated framing, reader thread."""

from __future__ import annotations

import contextlib
import logging
import os
import select
import socket
import threading
from collections.abc import Callable
from typing import Any

from .. import lockstep
from .frames import Authenticator, Decoder, Frame, FrameError, FrameType, encode
from .guid import guid_address, guid_text

LOG = logging.getLogger("ckm.link")
PROTOCOL = 1
HANDSHAKE_TIMEOUT = 3.0
SEND_TIMEOUT = 5.0
HANDSHAKE_MAX_FRAME = 4096  # until the peer is identified, a frame cannot be large
_HELLO_SESSION = b"ckm-hello"


class Link:
    """A connected socket to one remote peer (one edge of the mandala of §3.1.4.1, Fig. 3.5).

    Both ends send HELLO (GUID, name, fresh nonce); with a group key the HELLOs are
    authenticated and every later frame is bound to the session (both nonces), the sender's
    role and a sequence number. Until both HELLOs are exchanged the link carries nothing else.
    A frame that fails to decode closes the link with a logged reason; the peer goes on.
    """

    def __init__(
        self,
        sock: socket.socket,
        *,
        local_guid: int,
        local_name: str,
        max_frame: int,
        key: bytes | None,
        outgoing: bool,
        on_open: Callable[[Link], bool],
        on_frame: Callable[[Link, Frame], None],
        on_close: Callable[[Link, str], None],
        expected: int | None = None,
    ) -> None:
        self.sock = sock
        self.local_guid = local_guid
        self.local_name = local_name
        self.outgoing = outgoing
        self.expected = expected
        self.remote_guid: int | None = None
        self.remote_name = ""
        self.state = "handshake"
        self.closed_reason = ""
        self.frames_in = 0
        self.frames_out = 0
        self.last_received = lockstep.wall_monotonic()
        self._key = key
        self._nonce = os.urandom(16)
        self._auth = Authenticator(key, _HELLO_SESSION) if key is not None else None
        self._max_frame = max_frame
        self._decoder = Decoder(
            min(max_frame, HANDSHAKE_MAX_FRAME), auth=self._auth, direction=b"A" if outgoing else b"O"
        )
        self._send_lock = threading.Lock()
        self._on_open = on_open
        self._on_frame = on_frame
        self._on_close = on_close
        self._reader = threading.Thread(target=self._read_loop, name="ckm-link", daemon=True)

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Send our HELLO (GUID, name, nonce, protocol) and start the reader thread (§3.1.4.1)."""
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.settimeout(SEND_TIMEOUT)  # bounds sendall; reads wait in select
        hello = [self.local_guid, self.local_name, self._nonce, PROTOCOL]
        self._write(encode(FrameType.HELLO, hello, auth=self._auth, direction=b"O" if self.outgoing else b"A"))
        self._reader.start()

    def close(self, reason: str) -> None:
        """Close the connection once, recording ``reason``, and tell the owner."""
        with self._send_lock:
            if self.state == "closed":
                return
            self.state = "closed"
            self.closed_reason = reason
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
        self._on_close(self, reason)

    def join(self, timeout: float = 2.0) -> None:
        """Wait up to ``timeout`` s for the reader thread (not from the reader itself)."""
        if self._reader.is_alive() and threading.current_thread() is not self._reader:
            self._reader.join(timeout)

    # ------------------------------------------------------------------ sending

    def send(self, kind: FrameType, body: list[Any]) -> bool:
        """Send one frame; False (and the link closed) if the peer cannot take it."""
        if self.state != "open":
            return False
        with self._send_lock:
            if self.state != "open":
                return False
            data = encode(kind, body, auth=self._auth, direction=self._role())
            return self._write_locked(data)

    def send_encoded(self, data: bytes, *, wait: float | None = None) -> bool:
        """Send a frame encoded once for many links (only possible without a group key).

        ``wait``: the longest time to wait for another writer to finish; past it the frame is
        dropped (best-effort topics: a congested link loses samples rather than stalling).
        """
        if self.state != "open" or self._auth is not None:
            return False
        if not self._send_lock.acquire(timeout=-1 if wait is None else wait):
            return False
        try:
            return self.state == "open" and self._write_locked(data)
        finally:
            self._send_lock.release()

    def _write(self, data: bytes) -> None:
        with self._send_lock:
            self._write_locked(data)

    def _write_locked(self, data: bytes) -> bool:
        try:
            self.sock.sendall(data)
        except OSError as exc:
            threading.Thread(target=self.close, args=(f"send failed: {exc}",), daemon=True).start()
            return False
        self.frames_out += 1
        return True

    def _role(self) -> bytes:
        assert self.remote_guid is not None
        return b"L" if self.local_guid < self.remote_guid else b"H"

    # ------------------------------------------------------------------ receiving

    def _read_loop(self) -> None:
        deadline = lockstep.wall_monotonic() + HANDSHAKE_TIMEOUT
        reason = "closed by peer"
        try:
            while self.state != "closed":
                if self.state != "open" and lockstep.wall_monotonic() > deadline:
                    reason = "handshake timed out"
                    break
                # select, not a socket timeout: the socket's timeout bounds sends (SEND_TIMEOUT).
                readable, _, _ = select.select([self.sock], [], [], 0.2)
                if not readable:
                    continue
                data = self.sock.recv(262144)
                if not data:
                    if self._decoder.pending():
                        reason = f"truncated frame from {self._who()}: the stream ended inside a frame"
                        LOG.warning("link closed: %s", reason)
                    break
                self.last_received = lockstep.wall_monotonic()
                for frame in self._decoder.feed(data):
                    self.frames_in += 1
                    if self.state == "handshake":
                        self._handshake(frame)
                    elif self.state == "confirm":
                        self._confirm(frame)
                    elif self.state == "open":
                        self._dispatch(frame)
        except FrameError as exc:
            reason = f"bad frame from {self._who()}: {exc}"
            LOG.warning("link closed: %s", reason)
        except (OSError, ValueError) as exc:
            reason = f"socket error: {exc}"
        self.close(reason)

    def _dispatch(self, frame: Frame) -> None:
        try:
            self._on_frame(self, frame)
        except Exception:  # a listener's bug must not take the link down
            LOG.exception("listener failed on a %s frame from %s", frame.type.name, self._who())

    def _handshake(self, frame: Frame) -> None:
        body = frame.body
        valid = (
            frame.type == FrameType.HELLO
            and len(body) == 4
            and isinstance(body[0], int)
            and isinstance(body[1], str)
            and isinstance(body[2], bytes)
            and len(body[2]) == 16
            and body[3] == PROTOCOL
        )
        if not valid:
            raise FrameError("expected a HELLO frame to open the link")
        guid, name, nonce = body[0], body[1], body[2]
        try:
            address, _ = guid_address(guid)
        except ValueError:
            raise FrameError(f"HELLO carries an invalid GUID {guid}") from None
        if self.expected is not None and guid != self.expected:
            raise FrameError(f"connected to {guid_text(self.expected)} but it says it is {guid_text(guid)}")
        peer_host = self.sock.getpeername()[0]
        if address != peer_host:
            raise FrameError(f"GUID {guid_text(guid)} claimed from address {peer_host}")
        if guid == self.local_guid:
            raise FrameError("connected to itself")
        self.remote_guid = guid
        self.remote_name = name
        if self._auth is None:
            self._open()
            return
        # Key confirmation: a HELLO can be replayed, but only a key holder can answer in the new
        # session, which both nonces (one of them fresh from us) define.
        low, high = (self._nonce, nonce) if self.local_guid < guid else (nonce, self._nonce)
        self._auth.rekey(low + high)
        self._decoder.direction = b"H" if self.local_guid < guid else b"L"
        with self._send_lock:
            self.state = "confirm"
            self._write_locked(encode(FrameType.HELLO, ["confirm"], auth=self._auth, direction=self._role()))

    def _confirm(self, frame: Frame) -> None:
        if frame.type != FrameType.HELLO or frame.body != ["confirm"]:
            raise FrameError("expected the key confirmation")
        self._open()

    def _open(self) -> None:
        self._decoder.max_frame = self._max_frame
        with self._send_lock:
            self.state = "open"
        if not self._on_open(self):
            raise FrameError("refused by the peer's link policy")

    def _who(self) -> str:
        return guid_text(self.remote_guid) if self.remote_guid is not None else "an unidentified peer"
