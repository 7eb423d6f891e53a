"""``wait-signal`` in a live agent (runtime/missions/agent.py gives it its topics' arrival counts, D268):
a value published before its state began — the previous state's one-shot output — does not end it,
unless ``latched`` says such a value counts (what ``wait-input`` always does)."""

from __future__ import annotations

from pathlib import Path

import pytest

import tests.runtime.missions.test_behavior_topics as handover


@pytest.mark.parametrize(("latched", "outcome"), [("false", "lost"), ("true", "taken")])
def test_a_value_from_before_the_state_counts_only_when_latched(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                latched: str, outcome: str) -> None:
    waiting = handover.SYSTEM.replace(
        '<Behavior name="TAKE" kind="wait-input" timeout="3">',
        f'<Behavior name="TAKE" kind="wait-signal" timeout="1.5"><Param name="latched" value="{latched}"/>')
    assert waiting != handover.SYSTEM
    monkeypatch.setattr(handover, "SYSTEM", waiting)
    _, ended = handover.run_handover(tmp_path)
    assert ended == outcome
