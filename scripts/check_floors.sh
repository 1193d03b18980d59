#!/usr/bin/env bash
# The declared floors, tested (a stage of .ci/run; after scripts/setup.sh dev):
#  1. .venv-floor: vhgen with every direct dependency at the lowest version pyproject.toml
#     declares (uv --resolution lowest-direct); a person-only (local and Ray), a room and a
#     real-background job run end to end there and in .venv (the newest), read back with
#     vhgen.dataset, and hold the same arrays bit for bit;
#  2. each manifest opens with pyarrow alone: the floor's, the newest, and 18.1, 21 and 25
#     (the versions a user reported failing), whichever wrote it; and vhgen with each of
#     those pyarrow versions runs every kind of job to the same arrays;
#  3. a store of the old manifest form reads with vhgen under the floor's pyarrow.
# Usage: bash scripts/check_floors.sh [WORKDIR]   (default: .floors, removed at the end)
set -euo pipefail
cd "$(dirname "$0")/.."
work="${1:-.floors}"
uv=.venv/bin/uv
py="$(.venv/bin/python -c 'import sys, os; print(os.path.realpath(sys.base_prefix) + "/bin/python3")')"
rm -rf "$work" && mkdir -p "$work"
t0=$SECONDS

# 1. the floor venv, and every kind of job in both
rm -rf .venv-floor && $uv venv -q -p "$py" .venv-floor
VIRTUAL_ENV=.venv-floor $uv pip install -q --resolution lowest-direct -e .
.venv-floor/bin/vhgen assets fetch > /dev/null
.venv-floor/bin/python scripts/floors.py jobs "$work/floor"
.venv/bin/python scripts/floors.py jobs "$work/newest"
.venv/bin/python scripts/floors.py same "$work/floor" "$work/newest"

# 2. pyarrow alone, each version reads what each wrote
stores=$(ls -d "$work"/floor/*.zarr "$work"/newest/*.zarr)
.venv-floor/bin/python scripts/floors.py read $stores
.venv/bin/python scripts/floors.py read $stores
for v in 18.1.0 21.0.0 25.0.1; do
  env="$work/pyarrow-$v"
  $uv venv -q -p "$py" "$env"
  VIRTUAL_ENV="$env" $uv pip install -q "pyarrow==$v" "numpy<2"
  "$env/bin/python" scripts/floors.py read $stores
done

# 2b. vhgen itself with those pyarrow versions (the newest of everything else): every kind
#     of job writes, merges and reads back (pyarrow 25 could not merge a person-only job);
#     the job on Ray only with the first: its workers write the manifest parts with the
#     same code and pyarrow as the local executor's, and each Ray job costs ~20 s
jobs="person_only room real_background person_only_ray"  # (the cluttered job: floor and newest)
for v in 18.1.0 21.0.0 25.0.1; do
  env="$work/vhgen-pyarrow-$v"
  $uv venv -q -p "$py" "$env"
  VIRTUAL_ENV="$env" $uv pip install -q -e . "pyarrow==$v"
  "$env/bin/python" scripts/floors.py jobs "$work/with-pyarrow-$v" $jobs
  jobs="person_only room real_background"
  .venv/bin/python scripts/floors.py same "$work/newest" "$work/with-pyarrow-$v"
done

# 3. a store of manifest form 1 (null fixed-size lists): vhgen reads it with pyarrow 15
.venv/bin/python scripts/floors.py form1 "$work/newest/person_only.zarr" "$work/form1.zarr"
.venv-floor/bin/python scripts/floors.py vread "$work/form1.zarr"

rm -rf "$work" .venv-floor
echo "floors: every job ran and every manifest was read ($((SECONDS - t0)) s)"
