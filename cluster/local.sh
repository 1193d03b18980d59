#!/usr/bin/env bash
# A one-machine "cluster" for trying `ray job submit` locally (run from the repo root after
# scripts/setup.sh). Starts a Ray head from the project's virtualenv (so jobs use its
# Python), submits the default job, and stops the head.
set -euo pipefail
cd "$(dirname "$0")/.."
export RAY_AUTH_MODE=disabled   # Ray 2.60's `ray start` enables token auth otherwise
# the job's `python` is looked up on the PATH the head was started with: put the venv first
export PATH="$PWD/.venv/bin:$PATH"
ray start --head --num-cpus "${NUM_CPUS:-2}" --disable-usage-stats >/dev/null
trap 'ray stop >/dev/null' EXIT
ray job submit --working-dir . -- \
  python jobs/generate.py configs/scenes/default.yaml --out "$PWD/out/cluster.zarr" --overwrite
