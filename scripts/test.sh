#!/usr/bin/env bash
# Install everything the tests need on a fresh Debian machine, then run lint, types and tests.
# Usage: bash scripts/test.sh [pytest arguments]  (TDMON_TEST_WORKERS=N: pytest workers)
set -euo pipefail
cd "$(dirname "$0")/.."

# the system packages the tests use: a real MQTT broker, and headless Chromium that renders
# the report (tests/record/test_report_browser.py) and loads the live web view
missing=()
command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ] || missing+=(mosquitto)
# (chromium without its recommends, which pull in printing, Samba and a Perl web stack: 2.5
# minutes of CI; fonts-liberation, one of them, is the fonts the report's text is drawn in)
command -v chromium >/dev/null 2>&1 || missing+=(chromium fonts-liberation)
if [ ${#missing[@]} -gt 0 ]; then
    sudo_cmd=""
    [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends \
        "${missing[@]}"
fi

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test]"
# compile the model kernels into numba's on-disk cache now (a minute or so), not in the
# first test
.venv/bin/tdmon model warmup

.venv/bin/ruff check tdmon tests benchmarks
.venv/bin/mypy
# one pytest worker per core (pytest-xdist), whole files to a worker so that a file's
# module-scoped replays run once; TDMON_TEST_WORKERS=0 runs them in this process, one by one
.venv/bin/python -m pytest -n "${TDMON_TEST_WORKERS:-logical}" --dist loadfile "$@"
