#!/usr/bin/env bash
# Set everything up, then run the richest demo there is: validate and summarise the two-robot
# use case of the thesis (§7) and every example, and show how a broken file is reported.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ckm-validate --summary configs/usecase/lab.xml
.venv/bin/ckm-validate configs/usecase/*.xml configs/examples/*.xml configs/examples/split/*.xml
echo "all use-case and example files are valid"
echo "--- a broken file, as ckm-validate reports it:"
.venv/bin/ckm-validate configs/invalid/sensor_unknown_channel.xml || true
