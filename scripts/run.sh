#!/usr/bin/env bash
# Set everything up, then run the richest demo there is: validate and summarise the two-robot
# use case of the thesis (§7) and every example, run every node of both robots against the
# simulated laboratory, show how a broken file is reported, run a closed loop, a short version of
# the Smart Resource adaptation test of §7.2, the off-line mission validation and a two-agent plan
# with its report. (The group mission itself: scripts/mission.sh.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ckm-validate --schema-only --summary configs/usecase/lab.xml
.venv/bin/ckm-validate --schema-only configs/usecase/*.xml configs/examples/*.xml configs/examples/split/*.xml
echo "all use-case and example files are valid against the schema and their cross-references"
echo "--- the use case against the registered kinds (every service of Tables 7.1/7.2 runs):"
.venv/bin/ckm-validate configs/usecase/lab.xml
echo "--- every node of both robots against the simulated laboratory, 5 s on a clock slowed to a quarter:"
rm -rf runs/demo-lab
.venv/bin/ckm-run configs/usecase/lab.xml --duration 5 --time-scale 0.25 --log-dir runs/demo-lab
echo "--- a broken file, as ckm-validate reports it:"
.venv/bin/ckm-validate configs/invalid/sensor_unknown_channel.xml || true
echo "--- a closed loop on the loopback plant (run directory in runs/demo-closed-loop):"
.venv/bin/ckm-run configs/examples/closed_loop.xml --duration 3 --log-dir runs/demo-closed-loop
echo "--- §7.2: one to four clients on the RGB recognition service (figures in runs/demo-adaptation):"
.venv/bin/ckm-bench adaptation --phase 5 --schedule 1,2,3,4 --out runs/demo-adaptation
echo "--- §5.4: off-line validation of the use-case missions:"
.venv/bin/ckm-mission validate configs/usecase/lab.xml
echo "--- §5.3: a two-agent plan with a cross-agent signal, and its report (runs/demo-plan):"
rm -rf runs/demo-plan  # a run directory holds one run
.venv/bin/ckm-run configs/examples/plan_two_agents.xml --plan fetch-together --duration 30 --log-dir runs/demo-plan
.venv/bin/ckm-mission report runs/demo-plan
.venv/bin/ckm-mission report runs/demo-plan --html
