#!/usr/bin/env bash
# Create .venv (Python >= 3.11) and install the project with pinned versions; idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."

pick_python() {
    for candidate in "${PYTHON:-}" python3.11 python3.12 python3.13 python3; do
        [ -n "$candidate" ] || continue
        if command -v "$candidate" >/dev/null 2>&1 &&
            "$candidate" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; then
            echo "$candidate"
            return 0
        fi
    done
    echo "setup: Python 3.11 or newer is required" >&2
    return 1
}

if [ ! -x .venv/bin/python ]; then
    "$(pick_python)" -m venv .venv
fi
# the checkout's path is in the stamp: an editable install made from another checkout (a worktree sharing
# this .venv) points there, and its console scripts at that checkout's interpreter path
stamp=$( (cat pyproject.toml constraints.txt examples/ckm-example-plugins/pyproject.toml examples/ckm-lab/pyproject.toml; pwd -P) | sha256sum | cut -c1-16)
if [ "$(cat .venv/.ckm-installed 2>/dev/null || true)" != "$stamp" ]; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
    .venv/bin/python -m pip install --quiet --disable-pip-version-check -c constraints.txt -e ".[dev]"
    .venv/bin/python -m pip install -q -c constraints.txt -e examples/ckm-example-plugins
    # the thesis lab (D272): the toolkit runs without it; its tests, benchmarks and mission scripts use it
    .venv/bin/python -m pip install -q -c constraints.txt -e examples/ckm-lab
    echo "$stamp" > .venv/.ckm-installed
fi
# Byte-compile the project's own modules (an editable install leaves them as source): every process of a
# run imports them, and where PYTHONDONTWRITEBYTECODE is set each would compile them again at its start
# (1.2 s of a compact lock-step run's 7.9 s start-up; D242). Up-to-date files are skipped.
.venv/bin/python -m compileall -q -j 0 ckmconf runtime plugins editor benchmarks tests examples/ckm-example-plugins examples/ckm-lab >/dev/null
