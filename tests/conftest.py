"""Shared fixtures: the repository root and the configuration folders."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parent.parent
CONFIGS = REPO / "configs"

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

COMPACT_MISSION = "tests/benchmarks/test_compact_mission.py"
COMPACT_RUN = pytest.StashKey[Any]()  # the compact mission run started beside the suite (compact_run.Background)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The compact mission's tests go last: their run (minutes) goes on beside every other test."""
    compact = [item for item in items if item.nodeid.startswith(COMPACT_MISSION)]
    if compact:
        items[:] = [item for item in items if not item.nodeid.startswith(COMPACT_MISSION)] + compact


def pytest_collection_finish(session: pytest.Session) -> None:
    """Start the compact mission run (tests/benchmarks/compact_run.py) once its tests are selected."""
    config = session.config
    if config.option.collectonly or not any(item.nodeid.startswith(COMPACT_MISSION) for item in session.items):
        return
    from tests.benchmarks.compact_run import Background

    factory: pytest.TempPathFactory = config._tmp_path_factory  # type: ignore[attr-defined]
    config.stash[COMPACT_RUN] = Background(factory.mktemp("compact-mission"))


def pytest_sessionfinish(session: pytest.Session) -> None:
    """A run the session did not wait for (stopped early, -x) is stopped with it."""
    background = session.config.stash.get(COMPACT_RUN, None)
    if background is not None:
        background.stop()


def valid_files() -> list[Path]:
    """Every use-case and example file (Systems and Parts); each must validate on its own."""
    return sorted([*CONFIGS.glob("usecase/*.xml"), *CONFIGS.glob("examples/**/*.xml")])


@pytest.fixture
def repo() -> Path:
    return REPO


@pytest.fixture
def switching_often() -> Iterator[None]:
    """Threads switch every microsecond, not every 5 ms: a race shows in a short test."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    yield
    sys.setswitchinterval(before)
