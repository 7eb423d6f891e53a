"""configs/relay (issue N point 3b, README.md there): the depot relay of three robots of three shapes,
written with no code of its own. ``ckm-validate`` and ``ckm-mission validate`` accept it; the mistakes a
user porting it would likely make are refused at their FILE:LINE:COL; and a short run takes the failure
branch: the quad's mission ends in its failure final at once (its wait for the scout timed out), which
``lost('quad')`` reads as the quad lost (D177), so the scout and the rover go home and end ``recalled`` —
judged by where the world's own record (sim-final.json) has each robot. The full plan runs as a
benchmark (``ckm-bench mission --config configs/relay/relay.xml --plans relay``, README.md)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks.mission_scenarios import run_evidence
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

RELAY = REPO / "configs" / "relay"


def tool(name: str) -> str:
    return str(Path(sys.executable).parent / name)


def copy(tmp_path: Path, name: str = "", old: str = "", new: str = "") -> Path:
    """configs/relay copied to ``tmp_path``, with ``old`` replaced by ``new`` once in file ``name``."""
    target = tmp_path / "relay"
    shutil.copytree(RELAY, target, ignore=shutil.ignore_patterns("README.md"))
    if name:
        text = (target / name).read_text()
        assert text.count(old) >= 1, old
        (target / name).write_text(text.replace(old, new, 1))
    return target


def test_the_system_and_its_missions_are_valid() -> None:
    done = subprocess.run([tool("ckm-validate"), str(RELAY / "relay.xml")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    done = subprocess.run([tool("ckm-mission"), "validate", str(RELAY / "relay.xml")], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "plan relay: coherent (3 agents)" in done.stdout


MISTAKES = (  # file, text, replaced by, the text of the line it is refused at, what ckm-validate says
    ("plan.xml", '<Param name="input" value="scout"/>', '<Param name="input" value="scout_pose"/>', None,
     "parameter 'input' = 'scout_pose' is not one of its inputs (['scout'])"),
    ("plan.xml", '<Param name="take" value="position: pose.pose"/>', '<Param name="take" value="position: nav.pose"/>',
     None, "field 'position' takes from 'nav', which is not one of its inputs (['pose'])"),
    ("plan.xml", '<Param name="altitude" value="2.8"/>\n    <Uses service="Quad.Flight" as="flight"/>\n    <Input',
     '<Param name="goal" value="9 6 2.8"/>\n    <Param name="altitude" value="2.8"/>\n'
     '    <Uses service="Quad.Flight" as="flight"/>\n    <Input', '<Param name="goal" value="9 6 2.8"/>',
     "give parameter 'goal' or an input to fly over, not both"),
    ("plan.xml", '<Param name="dock" value="charger"/>', '<Param name="dock" value="chargr"/>', None,
     "parameter 'dock' = 'chargr' is no dock of the docking service RoverDock.Dock (its docks: charger); "
     "did you mean 'charger'?"),
    ("rover.xml", 'value="charger: 11.1 2.0 0"', 'value="charger: 11.1 2.0"', None,
     "parameter 'docks' for 'charger' needs 3 finite numbers"),
    ("plan.xml", "when=\"lost('quad') and not", "when=\"lost('drone') and not", None,
     "agent 'drone' does not exist in any plan"),
    ("plan.xml", '<Expect object="quadrotor"', '<Expect object="quadcopter"', None,
     "object 'quadcopter' does not exist in the environment or the simulated robots"),
    ("rover.xml", '<Param name="pose" value="11.1 2.0 0"/>', '<Param name="pose" value="11.7 2.0 0"/>', None,
     "inside 'charger'"),
)


IDS = ("navigate-to-input", "emit-signal-take", "fly-to-goal-and-input", "dock-robot-dock", "docking-docks",
       "lost-agent", "expect-object", "spawn-inside-charger")


@pytest.mark.parametrize(("name", "old", "new", "at", "message"), MISTAKES, ids=IDS)
def test_a_likely_mistake_is_refused_by_ckm_validate_at_its_line(
    tmp_path: Path, name: str, old: str, new: str, at: str | None, message: str
) -> None:
    target = copy(tmp_path, name, old, new)
    text = (target / name).read_text()
    line = text[: text.index(at or new)].count("\n") + 1
    done = subprocess.run([tool("ckm-validate"), str(target / "relay.xml")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert re.search(rf"{re.escape(str(target / name))}:{line}:\d+: .*{re.escape(message)}",
                     done.stdout + done.stderr), done.stdout + done.stderr


def test_a_quad_lost_at_the_start_sends_the_scout_and_the_rover_home(tmp_path: Path) -> None:
    """The failure branch on the lock-step clock, bounded: the quad gives up waiting after 2 s."""
    target = copy(tmp_path, "plan.xml", 'kind="wait-signal" progress="untraceable" timeout="240"\n'
                  '            description="Wait for the scout to reach the Pickup area."',
                  'kind="wait-signal" progress="untraceable" timeout="2"\n'
                  '            description="Wait for the scout to reach the Pickup area."')
    network = private_network()
    run_dir = tmp_path / "run"
    done = subprocess.run(
        [tool("ckm-run"), str(target / "relay.xml"), "--plan", "relay", "--lockstep", "0.01", "--duration", "60",
         "--log-dir", str(run_dir), "--ports", str(network.discovery_port), str(network.base_port)],
        cwd=REPO, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert done.returncode == 6, done.stdout[-2000:] + done.stderr[-2000:]  # no agent in its success final
    for agent, outcome in (("quad", "aborted"), ("scout", "recalled"), ("rover", "recalled")):
        assert f"{agent}: mission ended: {outcome}" in done.stdout, done.stdout[-2000:]
    states = {agent: [json.loads(line).get("state") for line in (run_dir / f"mission-{agent}.jsonl").open()]
              for agent in ("scout", "rover")}  # fmt: skip
    assert "RECALL" in states["scout"] and "REPORT" not in states["scout"]
    assert "UNDOCK" in states["rover"] and "RECALL" in states["rover"] and "TO_SCOUT" not in states["rover"]
    # The world's own record: each robot where the failure branch took it.
    evidence = {e["object"]: e for e in run_evidence(target / "relay.xml", "relay", run_dir) or []}
    assert evidence["scout"]["met"] is True, evidence  # back in ScoutDock
    assert evidence["rover"]["met"] is True, evidence  # docked again: its centre in RoverBay
    assert evidence["quadrotor"]["met"] is False  # still on pad_home, never over pad_pickup
    x, y, z = evidence["quadrotor"]["position"]
    assert abs(x - 1.5) < 0.4 and abs(y - 6.8) < 0.4 and z < 0.3, (x, y, z)
    status = json.loads((run_dir / "sim-final.json").read_text())["bodies"]["rover"]
    assert abs(status[5]) < 0.15, status  # facing the charger (east)
