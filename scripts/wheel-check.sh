#!/usr/bin/env bash
# The README's quick start from a wheel in a fresh environment (issue 33, item 3): build the
# wheel of this checkout, install it into a new virtual environment outside the checkout, and
# run the README's "Quick start, installed from a wheel" block there, as written, from a
# folder that knows nothing of the checkout. CI runs it (.ci/run; figures in docs/ci.md).
# Usage: bash scripts/wheel-check.sh [python3.X]   (default: python3)
# The dependencies come from pip's cache when it is warm (CI's other steps fill it).
set -euo pipefail
cd "$(dirname "$0")/.."
checkout=$PWD
python=${1:-python3}
work=$(mktemp -d "${TMPDIR:-/tmp}/tdmon-wheel-check.XXXXXX")
trap 'rm -rf "$work" "$checkout/build"' EXIT
start=$SECONDS

# the block under the quick start's heading, read from the README so that it cannot drift
quick_start=$(awk '
    /^## / { inside = ($0 ~ /^## Quick start, installed from a wheel/) }
    inside && /^```sh$/ { block = 1; next }
    inside && block && /^```/ { exit }
    inside && block { print }' README.md)
[ -n "$quick_start" ] || { echo "wheel-check: no quick start block in README.md" >&2; exit 1; }

rm -rf build
"$python" -m pip wheel -q --no-deps -w "$work/dist" .
echo "wheel-check: built $(basename "$work"/dist/*.whl) after $((SECONDS - start)) s"
"$python" -m venv "$work/env"
"$work/env/bin/python" -m pip install -q "$work"/dist/*.whl
echo "wheel-check: installed in a fresh environment after $((SECONDS - start)) s"

# the quick start, from an empty folder with the environment activated, as the README says
mkdir "$work/user"
cd "$work/user"
# shellcheck disable=SC1091
. "$work/env/bin/activate"
export MPLBACKEND=Agg
bash -euo pipefail -c "$quick_start"
cd "$work/user/tdmon-examples"
test -s out/trip-in-report/report.html
test -s out/trip-in-report/summary.json
echo "wheel-check: the README's quick start ran from the wheel in $((SECONDS - start)) s"
