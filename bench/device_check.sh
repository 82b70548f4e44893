#!/bin/bash
# pyclray's device tests and its GPU bench beside NVIDIA Warp (bench/gpu_warp.py) on a machine whose
# OpenCL device is a GPU and which reaches no package registry (a lent NVIDIA machine): the wheels it
# lacks come along in .whl/ and Warp in parts under .warp/ (both fetched here first by
# bench/device_wheels.sh), NVIDIA's OpenCL library is found and named to the ICD loader, and
# PYOPENCL_CTX selects its platform. Run from the repository's root:
#
#     bash bench/device_check.sh [all|tests|bench|stage|dry]   (default all; logs under $OUT if set)
#
# - stage: only keep the .warp/ parts this call carried in /tmp/warp-parts (Warp's wheel is larger than
#   what one call may carry: the calls before the last each carry one part and run `stage`; the last
#   carries .whl/ and the last part and runs `all`, which stages it too and unpacks Warp);
# - all: the device tests (TESTS, default the pair nodes' (one ray per work-item: a GPU's lane width,
#   held to the 8-lane path's bits on the device itself), the cast, render and device-array files;
#   TEST_S seconds, 150 by default) and bench.gpu_warp (BENCH_S seconds, 100 by default; its rows
#   "wide tree" the same kernels through the wide tree at one lane): under 5 minutes with the install;
# - dry: the same steps on this machine (PoCL on the CPU, Warp on the CPU, the checkout's .venv), at
#   small sizes, with no install and no NVIDIA library: the script checked end to end.
#
# The suite's other files need what does not travel (Mitsuba, Dask, ffmpeg): TESTS=tests runs them
# all, and those fail or skip there for that reason alone.
what=${1:-all}
out=${OUT:-/tmp/pyclray-device}
mkdir -p "$out"
exec > >(tee -a "$out/all.log") 2>&1
set -x
TESTS=${TESTS:-"tests/test_gpu_traversal.py tests/test_cast.py tests/test_cast_device.py tests/test_cast_blocks.py tests/test_all_hits.py tests/test_render.py"}
if [ "$what" = dry ]; then
    python=${PYTHON:-.venv/bin/python}
    [ -x "$python" ] || python=/work/main/.venv/bin/python
    export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
    "$python" -m pyclray devices || exit 1
    PYCLRAY_LANES=1 timeout "${TEST_S:-600}" "$python" -m pytest -q -x -p no:cacheprovider ${DRY_TESTS:-tests/test_cast_device.py} 2>&1 | tail -5
    PYCLRAY_LANES=1 timeout "${BENCH_S:-900}" "$python" -m bench.gpu_warp --rounds 1 --block 3 --size 128 --rays 100000 || exit 1
    exit 0
fi
mkdir -p /tmp/warp-parts
[ -d .warp ] && cp -n .warp/* /tmp/warp-parts/ 2>/dev/null
ls -la /tmp/warp-parts
[ "$what" = stage ] && exit 0
nvidia-smi -L
python3 --version
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir .whl/*.whl || exit 1
python3 -m pip install -q --no-index --no-deps --no-build-isolation -e . || exit 1
# Warp: its parts joined, checked against the sum device_wheels.sh wrote, unpacked onto the path
if ! python3 -c "import warp" 2>/dev/null; then
    (cd /tmp/warp-parts && cat warp.tar.xz.part* > warp.tar.xz && sha256sum -c warp.tar.xz.sha256) || exit 1
    mkdir -p /tmp/warp-site && tar -xJf /tmp/warp-parts/warp.tar.xz -C /tmp/warp-site || exit 1
    export PYTHONPATH=/tmp/warp-site${PYTHONPATH:+:$PYTHONPATH}
fi
lib=$(find / -xdev -name 'libnvidia-opencl.so*' 2>/dev/null | head -1)
[ -n "$lib" ] || { echo "no libnvidia-opencl.so on this machine"; exit 1; }
mkdir -p /tmp/icd && echo "$lib" > /tmp/icd/nvidia.icd
export OCL_ICD_VENDORS=/tmp/icd PYOPENCL_CTX=${PYOPENCL_CTX:-NVIDIA} PYTHONUNBUFFERED=1
python3 -m pyclray devices || exit 1
if [ "$what" = all ] || [ "$what" = tests ]; then
    timeout "${TEST_S:-150}" python3 -m pytest -q -n 12 -p no:cacheprovider --timeout 120 -rfE $TESTS \
        --junitxml="$out/junit.xml" 2>&1 | tail -60
fi
if [ "$what" = all ] || [ "$what" = bench ]; then
    timeout "${BENCH_S:-100}" python3 -m bench.gpu_warp --rounds 3 --block 5 | tee "$out/gpu_warp.md"
fi
nvidia-smi --query-gpu=name,clocks.sm,utilization.gpu --format=csv
