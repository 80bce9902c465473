#!/usr/bin/env bash
# Install tdmon in .venv and run the main job on the embedded default: the example well's loads
# and broomstick (hook load and torque against depth). Outputs go to out/.
set -euo pipefail
cd "$(dirname "$0")/.."

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e .

mkdir -p out
.venv/bin/tdmon model loads --well config/wells/aadnoy-example-7-1.toml --method soft-string
.venv/bin/tdmon model broomstick --well config/wells/aadnoy-example-7-1.toml \
    --mu 0.1,0.2,0.3 --png out/broomstick-example-7-1.png
.venv/bin/tdmon model broomstick --well config/wells/volve-f4.toml \
    --mu 0.15,0.25,0.35 --png out/broomstick-volve-f4.png
echo "figures in out/"
