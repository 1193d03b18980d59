#!/bin/bash
# Issue 28's checks and measurements on a GPU node, in one run of about 4 minutes (an H200
# and 16 cores: the GL sensor's tests on the GPU, where one worker's GL time and CPU time
# go, the description timing, then four 7,034-frame jobs at 350-500 frames/s):
#
#   bash benchmarks/gpu_node.sh [MOTIONS]          # in the project root, vhgen importable
#   bash .gpu/run.sh bash benchmarks/gpu_node.sh   # a node without network (gpu_bundle.sh)
#
# MOTIONS: a BVH folder (default ../shared/mocap/cmu; a node without network has no
# ../shared: copy the folder into the bundle and name it). PYTHON, WORKERS and BACKEND
# override python3, 16 and egl (BACKEND=osmesa WORKERS=2 FRAMES=96 tries it on a CPU);
# FRAMES the frames of each job (default all 7,034 of the plan at --frame-step 4).
# Prints: the GPU; the tests of the GL sensor against the CPU sensor (both row-scan
# layouts), of its batches and of their decoding, with the GPU's EGL (python -m pytest
# puts the checkout first on sys.path; no OSMesa there: its cases left out); bench_gpu.py
# --gl-calls (each GL call of a frame finished before the next: its GPU and driver time),
# with the row scans at 128 and at 1 invocations a row, and --profile (one worker's CPU by
# function, batch 4, layout_frames 16); the scene description's ms a frame with placement
# compiled and with its NumPy references (bench_placement.py, layout_frames 1 and 16);
# then the cluttered_room job (CMU corpus, clothed people, clutter, openni_525 with
# sensor.backend gl) with scene.layout_frames 16 and 1, each with render.batch_frames 4
# (batches, two in flight) and 0 (every frame read back before the next is drawn)
# (bench_gpu.py: frames/s over the dispatch and steady, GPU and CPU busy). Put the tables
# and this command in docs/performance.md.
set -u
M=${1:-../shared/mocap/cmu}
PY=${PYTHON:-python3}
W=${WORKERS:-16}
B=${BACKEND:-egl}
F=${FRAMES:-19200}
command -v nvidia-smi > /dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
nproc
"$PY" -m pytest -q -p no:cacheprovider -k "not osmesa" tests/render/test_sensor_gl.py \
    tests/render/test_frame_words.py tests/pipeline/test_gl_sensor_job.py
JOB=("$PY" benchmarks/bench_gpu.py --config cluttered_room --backend "$B" --sensor-backend gl
     --motions "$M" --frame-step 4)
"${JOB[@]}" --layout-frames 16 --batch-frames 4 --gl-calls 64 --row-threads 128,1
"${JOB[@]}" --layout-frames 16 --batch-frames 4 --workers "$W" --profile 512
"$PY" benchmarks/bench_placement.py --motions "$M" --frames 128 --repeat 3
"$PY" benchmarks/bench_placement.py --motions "$M" --frames 128 --repeat 3 --layout-frames 16
"${JOB[@]}" --workers "$W" --frames "$F" --layout-frames 16,1 --batch-frames 4,0
