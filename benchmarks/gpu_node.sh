#!/bin/bash
# Issue 28's measurements on a GPU node, in one run of about 4 minutes (an H200 and 16
# cores: six 4,800-frame jobs at 300-500 frames/s, their start-up, the description timing):
#
#   bash benchmarks/gpu_node.sh [MOTIONS]          # in the project root, vhgen importable
#   bash .gpu/run.sh bash benchmarks/gpu_node.sh   # a node without network (gpu_bundle.sh)
#
# MOTIONS: a BVH folder (default ../shared/mocap/cmu). PYTHON, WORKERS and BACKEND
# override python3, 16 and egl (BACKEND=osmesa WORKERS=2 FRAMES=96 tries it on a CPU).
# Prints: the GPU, the scene description's ms a frame with placement compiled and with
# its NumPy references (bench_placement.py: the node's CPU), then the cluttered_room job
# (CMU corpus, clothed people, clutter, openni_525 with sensor.backend gl) with
# scene.layout_frames 1 and 16, each with render.batch_frames 0 (every frame read back
# before the next is drawn), 1 and 4 (batches, two in flight) (bench_gpu.py: frames/s
# over the dispatch and steady, GPU and CPU busy). Put the tables and this command in
# docs/performance.md.
set -u
M=${1:-../shared/mocap/cmu}
PY=${PYTHON:-python3}
W=${WORKERS:-16}
B=${BACKEND:-egl}
F=${FRAMES:-4800}
command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
nproc
"$PY" benchmarks/bench_placement.py --motions "$M" --frames 128 --repeat 3
"$PY" benchmarks/bench_gpu.py --config cluttered_room --backend "$B" --sensor-backend gl \
    --motions "$M" --frame-step 4 --workers "$W" --frames "$F" --layout-frames 1,16 \
    --batch-frames 0,1,4
