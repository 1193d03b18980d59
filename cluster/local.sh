#!/usr/bin/env bash
# A one-machine "cluster" for trying `ray job submit` locally (run from the repo root after
# scripts/setup.sh). Starts a Ray head from the project's virtualenv (so jobs use its
# Python), submits the default job, and stops the head.
set -euo pipefail
cd "$(dirname "$0")/.."
export RAY_AUTH_MODE=disabled   # Ray 2.60's `ray start` enables token auth otherwise
.venv/bin/ray start --head --num-cpus "${NUM_CPUS:-2}" --disable-usage-stats
trap '.venv/bin/ray stop' EXIT
.venv/bin/ray job submit --working-dir . -- \
  python jobs/generate.py configs/scenes/default.yaml --out "$PWD/out/cluster.zarr" --overwrite
