"""Joining the network: the first step of every host of this process (§3.1.4, issue H point 2).

``ckm-run`` (:mod:`runtime.cli`), the configuration agent (:mod:`runtime.distribution`) and the
benchmarks' nodes (``benchmarks/``) all join the network of a ``<Network>`` element the same
way: read the group key file next to the configuration, open the transport the element asks
for (CKMultiPeer or Zenoh), subscribe the host's network-event callback, set it up, start it.
The whole host (:mod:`runtime.host`) sits above the kernel; this part needs only the network
layer, so a benchmark's worker process joins without loading the kernel.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

from ckmconf.model import Network

from . import lockstep
from .network import NetworkEvent, Transport, open_transport, read_group_key
from .network.api import GroupKeyError, NetworkError
from .network.guid import guid_text

LOG = logging.getLogger("ckm.run")
PORTS_VARIABLE = "CKM_NETWORK_PORTS"
"""``DISCOVERY BASE``: the network ports of every process of a run, instead of its ``<Network>``'s
(``ckm-run --ports``, D258); the run's partitions inherit it."""
ANSWER_WAIT = 0.25
"""Wall seconds after joining by which the peers already on the network have answered (they answer a
newcomer's announcement within 5 ms; a loaded machine adds some)."""


def parse_ports(text: str, where: str = PORTS_VARIABLE) -> tuple[int, int]:
    """(discovery, base) from ``DISCOVERY BASE``: two different ports in 1024-65535; ValueError naming ``where``."""
    try:
        discovery, base = (int(word) for word in text.split())
    except ValueError:
        raise ValueError(f"{where} = {text!r}: expected two port numbers, DISCOVERY BASE") from None
    if not (1024 <= discovery <= 65535 and 1024 <= base <= 65535) or discovery == base:
        raise ValueError(f"{where} = {text!r}: expected two different ports in 1024-65535")
    return discovery, base


def with_ports(network: Network, environ: Mapping[str, str] | None = None) -> Network:
    """``network`` on the ports ``CKM_NETWORK_PORTS`` names, if it is set (D258)."""
    text = (os.environ if environ is None else environ).get(PORTS_VARIABLE, "").strip()
    if not text:
        return network
    discovery, base = parse_ports(text)
    return dataclasses.replace(network, discovery_port=discovery, base_port=base)


class JoinError(Exception):
    """The network could not be joined (a bad group key file, a port in use, no Zenoh router…).

    Its text is ``cannot join the network: REASON``; the host prefixes where (the configuration
    file) and exits with ``EXIT_NETWORK`` (docs/exit-codes.md).
    """


def join(
    network: Network,
    name: str,
    *,
    key_dir: Path | None = None,
    on_event: Callable[[NetworkEvent], None] | None = None,
) -> Transport:
    """Open and set up (not start) the transport of a ``<Network>`` element.

    Args:
        network: the ``<Network>`` record (``Network()`` for the default one).
        name: this peer's name on the network (the node, ``NODE.PARTITION``, the agent).
        key_dir: the directory the ``groupKeyFile`` attribute is relative to; None reads no
            key (the agent without a bootstrap file).
        on_event: called for every network event (peer found, lost, a missed deadline).

    Returns:
        The transport, set up: its sockets are open, nothing is sent until ``start()``.

    Raises:
        JoinError: the key cannot be read or the transport cannot be set up.
    """
    try:
        network = with_ports(network)
        key = read_group_key(network, key_dir) if key_dir is not None else None
        transport = open_transport(network, name=name, key=key)
        if on_event is not None:
            transport.on_event(on_event)
        transport.setup()
    except (GroupKeyError, NetworkError, OSError, ValueError) as exc:
        raise JoinError(f"cannot join the network: {exc}") from exc
    return transport


@contextlib.contextmanager
def joined(network: Network, name: str, *, key_dir: Path | None = None, start: bool = True) -> Iterator[Transport]:
    """The transport of ``network``, set up (and started unless ``start`` is False) for the
    ``with`` block and stopped when it ends, however it ends.

    Args:
        network: the ``<Network>`` record.
        name: this peer's name on the network.
        key_dir: the directory of the group key file, as for :func:`join`.
        start: False leaves ``start()`` to the block (a benchmark timing its peers' start).
    """
    transport = join(network, name, key_dir=key_dir)
    try:
        if start:
            transport.start()
        yield transport
    finally:
        transport.stop()


class Namesakes:
    """Other peers announcing this process's own name: another run of the same system on the same
    network (D257). Each run's frames would reach the other's topics, and neither would say so (two
    lab missions started side by side both ended in SPOT loops). Feed it the network events; before
    the nodes start, :meth:`clash` is the error to stop on; a namesake heard later is warned about."""

    def __init__(self, name: str, network: Network) -> None:
        self.name, self.network = name, network
        self.peers: list[int] = []
        self.started = False  # this run's nodes are running: a later namesake is a newcomer's to refuse
        self.joined = lockstep.wall_monotonic()
        self._lock = threading.Lock()

    def listening(self) -> None:
        """The transport has started: the peers on the network answer from now."""
        self.joined = lockstep.wall_monotonic()

    def heard(self, event: NetworkEvent) -> None:
        """Note a peer found under this process's name."""
        if event.kind != "found" or event.detail != self.name or event.peer is None:
            return
        with self._lock:
            if event.peer in self.peers:
                return
            self.peers.append(event.peer)
            started = self.started
        if started:
            LOG.warning("another peer named %r joined the network at %s: %s", self.name, self._where(event.peer),
                        self._advice())

    def clash(self) -> str | None:
        """The error to stop on if a namesake was heard (None: none), once the peers had ANSWER_WAIT
        to answer; afterwards only warnings."""
        left = ANSWER_WAIT - (lockstep.wall_monotonic() - self.joined)
        if left > 0:  # on the wall clock: in lock-step the run's clock is held meanwhile (nothing runs yet)
            lockstep.real("sleep")(left)
        with self._lock:
            self.started = True
            peers = list(self.peers)
        if not peers:
            return None
        where = ", ".join(self._where(peer) for peer in peers)
        return f"cannot join the network: another peer named {self.name!r} is on it, at {where}: {self._advice()}"

    def _where(self, peer: int) -> str:
        return guid_text(peer) if 0 < peer < 1 << 48 else str(peer)

    def _advice(self) -> str:
        net = self.network
        return (f"another run of this system on group {net.group}:{net.discovery_port}? Stop it, or run this one "
                "on other ports (ckm-run --ports DISCOVERY BASE), or give it a <Network> of its own")
