#!/bin/bash
# pyclray's suite and bench.device on a machine whose OpenCL device is a GPU and which reaches no
# package registry (a lent NVIDIA machine): the wheels it lacks come along in .whl/ (fetched here
# first by bench/device_wheels.sh), NVIDIA's OpenCL library is found and named to the ICD loader,
# and PYOPENCL_CTX selects its platform. Run from the repository's root:
#
#     bash bench/device_check.sh [all|tests|bench]      (default all; logs under $OUT if set)
#
# The suite runs without CI=true: the tests that need Mitsuba, Dask or ffmpeg (not carried: Mitsuba's
# wheels alone exceed a 64 MiB transfer) fail or skip there for that reason alone.
what=${1:-all}
out=${OUT:-/tmp/pyclray-device}
mkdir -p "$out"
exec > >(tee "$out/all.log") 2>&1
set -x
nvidia-smi -L
python3 --version
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir .whl/*.whl || exit 1
python3 -m pip install -q --no-index --no-deps --no-build-isolation -e . || exit 1
lib=$(find / -xdev -name 'libnvidia-opencl.so*' 2>/dev/null | head -1)
[ -n "$lib" ] || { echo "no libnvidia-opencl.so on this machine"; exit 1; }
mkdir -p /tmp/icd && echo "$lib" > /tmp/icd/nvidia.icd
export OCL_ICD_VENDORS=/tmp/icd PYOPENCL_CTX=${PYOPENCL_CTX:-NVIDIA} PYTHONUNBUFFERED=1
python3 -m pyclray devices || exit 1
python3 -m pyclray render scenes/tp02.toml -o "$out/tp02.exr" --png || exit 1
if [ "$what" = all ] || [ "$what" = tests ]; then
    timeout "${TEST_S:-330}" python3 -m pytest -q -n 12 -p no:cacheprovider --timeout 120 -rfE "${TESTS:-tests}" \
        --junitxml="$out/junit.xml" 2>&1 | tail -120
fi
if [ "$what" = all ] || [ "$what" = bench ]; then
    timeout "${BENCH_S:-170}" python3 -m bench.device --rounds 3 --block 5
fi
nvidia-smi --query-gpu=name,clocks.sm,utilization.gpu --format=csv
