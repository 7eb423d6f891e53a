"""Fixtures: the use-case lab's map and the zoom-map example, built from their configuration files."""

from __future__ import annotations

import pytest

import ckmconf
from ckmconf.model.environment import Environment
from plugins.environment.map_model import MapModel
from tests.conftest import CONFIGS


def environment(path: str) -> Environment:
    env = ckmconf.load(CONFIGS / path).environment
    assert env is not None
    return env


@pytest.fixture
def lab_env() -> Environment:
    return environment("usecase/environment.xml")


@pytest.fixture
def lab(lab_env: Environment) -> MapModel:
    return MapModel.from_environment(lab_env)
