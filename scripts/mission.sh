#!/usr/bin/env bash
# The two-robot group mission of the thesis (§7.3–7.5) in the simulated laboratory: validate it
# off-line (§5.4), run it (every node, the world server, both agents), then write the run's HTML
# report. Usage: bash scripts/mission.sh [cooperative|individual] [CLOCK] [lab|compact]
# The cooperative mission (Fig. 7.13) is the default: the Nao spots the red cylinder and signals
# where it is, the Turtlebot fetches it from the workbench and puts it on the drop table.
# CLOCK is `lockstep` (the default: every process of the run on one simulated clock, D190/D230; the
# run goes as fast as the machine allows and the machine's load cannot change it: the lab's
# mission, ~90-120 s simulated, takes about 4 minutes here) or a time scale such as 0.2 (every
# clock slowed so that a two-core machine keeps up with the recognition's deadlines, Table 7.3, as on
# the thesis' machine: about 9 minutes). The compact layout (benchmarks/mission_compact.py, D205: the
# same system, the drop table next to the workbench) takes about 2. Exits with ckm-run's code (0:
# every agent succeeded); the world's own end record (sim-final.json) says where the object was left.
set -euo pipefail
cd "$(dirname "$0")/.."
plan="${1:-cooperative}"
clock="${2:-lockstep}"
layout="${3:-lab}"
case "$clock" in
    lockstep) clock_options=(--lockstep 0.01) ;;
    *[!0-9.]*|'') echo "mission.sh: the clock must be lockstep or a time scale such as 0.2, not '$clock'" >&2; exit 2 ;;
    *) clock_options=(--time-scale "$clock") ;;
esac
bash scripts/setup.sh
run="runs/${layout}-${plan}"
rm -rf "$run"
mkdir -p "$run"
config=configs/usecase/lab.xml
case "$layout" in
    lab) ;;
    compact)
        config="$run/config/lab.xml"
        .venv/bin/python -c "import sys; from pathlib import Path; from benchmarks.mission_compact import compact
compact(Path('configs/usecase/lab.xml'), Path(sys.argv[1]))" "$run/config" ;;
    *) echo "mission.sh: layout must be lab or compact, not '$layout'" >&2; exit 2 ;;
esac
.venv/bin/ckm-mission validate "$config"
.venv/bin/ckm-mission validate --json "$config" | tail -n 1 > "$run/validation.json"
topics=/nav/pose,/nav/status,/base/odom,/base/path,/base/move_status,/arm/status,/recog/objects
topics=$topics,/rgbd/rgb/objects,/rgbd/depth/objects,/pantilt/objects,/pantilt/target,/agent1/target
topics=$topics,/sim/turtlebot/pose
# Navigation's own zoom-map areas (the report's Fig. 7.16) and its particle cloud every 4 s (6.4 kB each, D217)
topics=$topics,/nav/zoom,/nav/particles@0.25
# the cameras at most every 2 s as JPEG CompressedImage (10-17 kB, not 900 kB, a frame): the report's snapshots (D197)
topics=$topics,/turtlebot/~xtion_rgb_raw@0.5:jpeg,/nao/camera/image@0.5:jpeg
status=0
.venv/bin/ckm-run "$config" --plan "$plan" "${clock_options[@]}" --duration 900 \
    --log-dir "$run/run" --record "$topics" --record-format mcap+sqlite3 || status=$?
cp "$run/validation.json" "$run/run/validation.json"
.venv/bin/ckm-mission report "$run/run" --html --config "$config" || [ "$status" -ne 0 ] || status=1
# ckm-mission report has printed where the report is
exit "$status"
