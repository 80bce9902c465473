#!/usr/bin/env bash
# Create the benchmark's own virtualenv (benchmarks/.venv) with the peer packages and tdmon.
# The peers are never project dependencies: they live only here.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python="${PYTHON:-python3}"
"$python" -m venv "$here/.venv"
"$here/.venv/bin/python" -m pip install --quiet --upgrade pip
"$here/.venv/bin/python" -m pip install --quiet "welleng==0.30.0" "torque_drag==0.1.1"
"$here/.venv/bin/python" -m pip install --quiet -e "$here/.."
"$here/.venv/bin/python" -m pip list 2>/dev/null | grep -i -E "^(welleng|torque.drag|tdmon|numpy|numba) "
