"""``behavior.init`` and ``behavior.end``: the mission marks that use no service (Table 7.5's INIT and END)."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from plugins.behaviors.mission_marks import End, Init
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from tests.plugins.navigation.loop import room


def record(kind: str, **params: str) -> BehaviorRecord:
    return BehaviorRecord(name=kind.upper(), kind=kind, timeout=5.0,
                          params=tuple(Param(name=k, value=v) for k, v in params.items()))


def context() -> BehaviorContext:
    return BehaviorContext(services={}, inputs={}, outputs={}, now=lambda: 0.0)


def test_init_is_done_at_once_and_says_what_the_mission_is_after() -> None:
    init = Init(record("init", target="parcel", home="Start"), context())
    init.start()
    status = init.step()
    assert status.done and status.progress == 1.0 and status.detail == "target parcel"
    assert init.params["home"] == "Start"


def test_end_is_done_at_once() -> None:
    end = End(record("end"), context())
    end.start()
    status = end.step()
    assert status.done and not status.failed and status.progress == 1.0


def test_a_param_the_marks_do_not_take_is_refused_naming_the_behavior() -> None:
    with pytest.raises(ParamError, match=r"behavior 'INIT' \(init\).*'goal'"):
        Init(record("init", goal="Start"), context())
    with pytest.raises(ParamError, match=r"behavior 'END' \(end\).*'target'"):
        End(record("end", target="parcel"), context())


def test_a_home_naming_no_area_of_the_map_is_a_problem(tmp_path: Path) -> None:
    system = ckmconf.load(room(tmp_path))
    assert Init.problems(record("init", home="Start"), system) == []
    assert Init.problems(record("init", home="Start"), None) == []  # no map to check against
    ((where, message),) = Init.problems(record("init", home="Hom"), system)
    assert isinstance(where, Param) and where.value == "Hom"
    assert message.startswith("parameter 'home' = 'Hom' is no Area of the map (its Areas: ['Start', 'Target'")
