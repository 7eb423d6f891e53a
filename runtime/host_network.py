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
from collections.abc import Callable, Iterator
from pathlib import Path

from ckmconf.model import Network

from .network import NetworkEvent, Transport, open_transport, read_group_key
from .network.api import GroupKeyError, NetworkError


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
