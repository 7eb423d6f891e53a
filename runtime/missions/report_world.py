"""The simulated world of a run in the HTML report: scenario, disturbances fired, bodies at the end (D171, D178).

The world server (plugins/sim/server.py) leaves in the run directory ``sim-final.json`` at its end
(simulated ``time``, ``positions`` of the movable bodies, the ``scenario`` file it was given and
the fired ``disturbances``) and ``sim-disturbances.json`` as each disturbance fires, so a server
that was killed still tells what was done to the world. Each disturbance is
``{time, line, event, body, position}``: simulated seconds, the scenario line, its text, the body
it moved and where that body was left.
"""

from __future__ import annotations

import json
from html import escape
from pathlib import Path
from typing import Any


def _bad(path: Path, error: Exception) -> str:
    return f'<span class="bad">{escape(path.name)}: unreadable: {escape(str(error))}</span>'


def _xyz(values: Any) -> str:
    return ", ".join(f"{float(v):.2f}" for v in values)


def _read(path: Path) -> Any:
    return json.loads(path.read_text(encoding="utf-8"))


def disturbance_line(event: Any) -> str:
    """One fired disturbance: ``at 12.3 s (line 4): move crate to 2 3; crate at (2.00, 3.00, 0.10)``."""
    if not isinstance(event, dict):
        raise TypeError(f"a disturbance is {event!r}, not an object")
    where = f"; {escape(str(event['body']))} left at ({_xyz(event['position'])})" if event.get("body") else ""
    line = f" (scenario line {int(event['line'])})" if event.get("line") is not None else ""
    return f"at {float(event['time']):.1f} s{line}: {escape(str(event['event']))}{where}"


def world_rows(run_dir: Path) -> list[list[str]]:
    """The summary rows about the world: where the bodies ended, the scenario, each disturbance fired."""
    finals = sorted(run_dir.glob("sim-final*.json"))
    positions: list[str] = []
    scenarios: list[str] = []
    fired: dict[str, list[Any]] = {}  # per world server (its suffix), the disturbances it fired
    problems: list[str] = []
    for path in finals:
        try:
            final = _read(path)
            for name, xyz in final["positions"].items():
                positions.append(f"{escape(str(name))} ({_xyz(xyz)})")
            scenario = final.get("scenario")
            scenarios.append(f"{escape(Path(scenario).stem)} ({escape(str(scenario))})" if scenario else "none")
            fired[path.name.replace("sim-final", "")] = list(final.get("disturbances") or [])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
            problems.append(_bad(path, error))
    for path in sorted(run_dir.glob("sim-disturbances*.json")):  # a server killed before its sim-final.json
        key = path.name.replace("sim-disturbances", "")
        if key in fired:
            continue
        try:
            events = _read(path)
            fired[key] = list(events) if isinstance(events, list) else []
        except (OSError, ValueError) as error:
            problems.append(_bad(path, error))
    if not finals and not fired and not problems:
        return [["World at the end", "no simulated world (no sim-final.json)"]]
    lines: list[str] = []
    for events in fired.values():
        for event in events:
            try:
                lines.append(disturbance_line(event))
            except (KeyError, TypeError, ValueError) as error:
                lines.append(f'<span class="bad">a disturbance unreadable: {escape(str(error))}</span>')
    scenario = ", ".join(dict.fromkeys(scenarios)) or "unknown (no sim-final.json: the world server did not finish)"
    if scenario == "none":
        scenario = "none: the world was not disturbed"
    done = f"{len(lines)} fired:<br>" + "<br>".join(lines) if lines else "none fired"
    rows = [
        ["World at the end", ", ".join(positions) or "unknown (no sim-final.json)"],
        ["World scenario", scenario],
        ["Disturbances", done],
    ]
    if problems:
        rows[0][1] = "<br>".join([rows[0][1], *problems])
    return rows
