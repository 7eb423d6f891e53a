"""Shared fixtures: the repository root and the configuration folders."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
CONFIGS = REPO / "configs"

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def valid_files() -> list[Path]:
    """Every use-case and example file (Systems and Parts); each must validate on its own."""
    return sorted([*CONFIGS.glob("usecase/*.xml"), *CONFIGS.glob("examples/**/*.xml")])


@pytest.fixture
def repo() -> Path:
    return REPO
