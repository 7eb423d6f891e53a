"""ckm-run's hook for run-wide hardware sessions (runtime.sessions, D102): the ``run_session`` of each
backend kind the nodes use is entered once before the run and left after it, through the registry;
``hardware.sim`` has one (its world server)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import Node, System
from plugins.hardware.loopback import LoopbackBackend
from plugins.hardware.sim import SimBackend
from runtime.registry import Registry, default_registry
from runtime.sessions import HardwareSessions

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="sessions">
  <Node name="a">
    <HWChannel name="x" direction="in" backend="recorded"/>
    <HWChannel name="y" direction="in" backend="recorded"/>
    <HWChannel name="z" direction="in" backend="plain"/>
  </Node>
  <Node name="b">
    <HWChannel name="w" direction="in" backend="unreachable"/>
  </Node>
</System>
"""
journal: list[str] = []


class Recorded(LoopbackBackend):
    """A loopback channel whose kind also keeps a run-wide session (writes the journal)."""

    @classmethod
    @contextlib.contextmanager
    def run_session(
        cls, system: System, config: Path, run_dir: Path, nodes: Sequence[Node], failed: Callable[[str], None]
    ) -> Iterator[None]:
        journal.append(f"enter {system.name} {[n.name for n in nodes]} {run_dir.name}")
        failed("told")
        try:
            yield
        finally:
            journal.append("exit")


class Broken(LoopbackBackend):
    @classmethod
    def run_session(cls, *args: Any) -> contextlib.AbstractContextManager[None]:
        raise RuntimeError("the bus daemon is not installed")


@pytest.fixture
def setting(tmp_path: Path) -> tuple[System, Registry]:
    journal.clear()
    registry = Registry(load_entry_points=False)
    registry.register("hardware", "recorded", Recorded)
    registry.register("hardware", "plain", LoopbackBackend)
    registry.register("hardware", "unreachable", Broken)
    return ckmconf.load_bytes(SYSTEM.encode(), str(tmp_path / "sessions.xml")), registry


def test_each_kind_is_entered_once_and_left_at_stop(setting: tuple[System, Registry], tmp_path: Path) -> None:
    system, registry = setting
    told: list[str] = []
    sessions = HardwareSessions(system, tmp_path / "s.xml", tmp_path / "run", system.nodes[:1], told.append, registry)
    sessions.start()
    assert journal == ["enter sessions ['a'] run"] and told == ["told"]  # two channels, one session
    sessions.stop()
    sessions.stop()  # idempotent
    assert journal == ["enter sessions ['a'] run", "exit"]


def test_a_failing_session_propagates_and_the_entered_ones_are_left(
    setting: tuple[System, Registry], tmp_path: Path
) -> None:
    system, registry = setting
    sessions = HardwareSessions(system, tmp_path / "s.xml", tmp_path / "run", system.nodes, lambda _: None, registry)
    with pytest.raises(RuntimeError, match="not installed"):
        sessions.start()  # name order: "recorded" is entered, then "unreachable" fails
    assert journal == ["enter sessions ['a', 'b'] run"]
    sessions.stop()  # what ckm-run's finally does
    assert journal == ["enter sessions ['a', 'b'] run", "exit"]


def test_the_sim_backend_exposes_its_world_server_session() -> None:
    backend = default_registry().find("hardware", "sim")
    assert backend is SimBackend and callable(getattr(backend, "run_session", None))
    assert getattr(default_registry().find("hardware", "loopback"), "run_session", None) is None
