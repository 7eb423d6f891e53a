"""The cooperative mission of Fig. 7.13 to success in CI (issue K points 6 and 7): the whole use
case — every node of both robots, the world server, both agents' missions over CKMultiPeer — run by
``ckm-run --lockstep`` on the compact copy of the lab (benchmarks/mission_compact.py, D205: the same
system, the drop table next to the workbench), on a private network. On the lock-step clock (D190,
D220) every process waits for the others and for the frames between them, so the run does not
depend on how loaded the machine is: the same seed gives the same run.

Success is judged on the world's own evidence, not only on the missions' outcomes: the grasp held
the cylinder (the world server's log), and the world's final record has it standing on the drop
table. The recording then reproduces the off-line validation (§7.5: every state the agents
entered was a step of an off-line episode), and the report's Table 7.9 agrees with the recording.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import ckmconf
from benchmarks.mission_compact import DROP_TABLE
from runtime.missions.recording import read_run
from runtime.missions.report import build_report
from runtime.missions.validation.online import replay
from tests.benchmarks.compact_run import Background
from tests.conftest import COMPACT_RUN

TABLE_TOP = 0.30
CYLINDER_HALF_HEIGHT = 0.06


@pytest.fixture(scope="module")
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, int | None]:
    """The run the suite started beside the other tests (tests/conftest.py), else one started now."""
    background = request.config.stash.get(COMPACT_RUN, None)
    if background is None:
        background = Background(tmp_path_factory.mktemp("compact-mission"), niceness=0)
    result = background.result()
    return Path(result["config"]), background.root / "run", result["code"]


@pytest.mark.timeout(1200)
def test_both_robots_complete_the_cooperative_mission_by_doing_the_work(run: tuple[Path, Path, int | None]) -> None:
    config, run_dir, code = run
    log = (run_dir.parent / "run.log").read_text()
    assert code == 0, log[-3000:]
    recorded = read_run(run_dir)
    assert {a: r.outcome for a, r in recorded.agents.items()} == {"turtlebot": "succeeded", "nao": "spotted"}
    grasps = (run_dir / "sim-server.log").read_text()
    assert "caught body" in grasps and "let go" in grasps  # the arm really held it, then put it down
    final = json.loads((run_dir / "sim-final.json").read_text())
    x, y, z = final["positions"]["cylinder_red_stripes"]
    assert abs(x - DROP_TABLE[0]) < 0.3 and abs(y - DROP_TABLE[1]) < 0.3  # on the drop table's top ...
    assert z == pytest.approx(TABLE_TOP + CYLINDER_HALF_HEIGHT, abs=0.02)  # ... standing, not lying or fallen
    system = ckmconf.load(config)
    plan = system.plan("cooperative")
    assert plan is not None
    for agent in plan.agents:
        verdict = replay(system, agent.mission, agent.name, recorded.of(agent.name))
        assert verdict.divergence is None, verdict.describe()  # every step was taken off-line too


@pytest.mark.timeout(1200)
def test_the_reports_table_agrees_with_the_recording(run: tuple[Path, Path, int | None]) -> None:
    _, run_dir, _ = run
    recorded = read_run(run_dir)
    for agent in build_report(recorded).agents:
        events = [e for e in recorded.of(agent.agent) if e.kind in ("enter", "exit")]
        total = sum(row.time for row in agent.rows)
        span = recorded.agents[agent.agent].finish - recorded.agents[agent.agent].begin
        assert total == pytest.approx(span, abs=0.5)  # the rows cover the mission
        assert sum(sum(row.contribution) for row in agent.rows) == pytest.approx(1.0, abs=0.01)
        entered = {str(e.get("path")).split("/", 1)[-1] for e in events
                   if e.kind == "enter" and e.get("nested") is None}  # fmt: skip
        assert {row.label for row in agent.rows} == entered
        assert all(math.isfinite(row.time) and row.time >= 0 for row in agent.rows)
