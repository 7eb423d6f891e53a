"""PROXYWRAPPER: two peers that cannot connect to each other talk through a third.

Inside a private network namespace three peers live on 127.0.0.2, .3 and .4; policy-routing
rules forbid any packet between .2 and .4, so only the relay on .3 links to both. Multicast
still reaches everyone, so the two ends know of each other and must fall back to the relay.
"""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import REPO

PEER = Path(__file__).with_name("proxy_peer.py")


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


@pytest.fixture
def namespace() -> Iterator[str]:
    name = f"ckm-proxy-{uuid.uuid4().hex[:8]}"
    try:
        ip("netns", "add", name)
    except (subprocess.CalledProcessError, FileNotFoundError) as exc:
        pytest.skip(f"cannot create a network namespace here (needs root and iproute2): {exc}")
    try:
        ip("-n", name, "link", "set", "lo", "up")
        ip("-n", name, "link", "set", "lo", "multicast", "on")
        ip("-n", name, "route", "add", "224.0.0.0/4", "dev", "lo")
        # Move the local table below our rules, then forbid .2 <-> .4 in both directions.
        ip("-n", name, "rule", "add", "pref", "100", "lookup", "local")
        ip("-n", name, "rule", "del", "pref", "0")
        ip("-n", name, "rule", "add", "pref", "10", "from", "127.0.0.2", "to", "127.0.0.4", "prohibit")
        ip("-n", name, "rule", "add", "pref", "11", "from", "127.0.0.4", "to", "127.0.0.2", "prohibit")
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=10)


def start(namespace: str, role: str, address: str) -> subprocess.Popen[str]:
    command = ["ip", "netns", "exec", namespace, sys.executable, str(PEER), role, address, "25000"]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_peers_without_a_direct_path_talk_through_a_relay(namespace: str) -> None:
    peers = [start(namespace, "relay", "127.0.0.3"), start(namespace, "talk", "127.0.0.4")]
    listener = start(namespace, "listen", "127.0.0.2")
    try:
        out, err = listener.communicate(timeout=30)
    finally:
        for process in [listener, *peers]:
            process.kill()
            process.wait(timeout=10)
    assert listener.returncode == 0, err
    [line] = out.splitlines()
    report = json.loads(line)
    assert report["got"] == "hello from 127.0.0.4"
    assert report["from"].startswith("127.0.0.4:")
    assert report["routes"][report["from"]].startswith("127.0.0.3:")
    assert all(not d.startswith("127.0.0.4:") for d in report["direct"])
