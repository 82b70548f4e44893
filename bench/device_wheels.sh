#!/bin/bash
# The wheels bench/device_check.sh installs on a machine that reaches no registry (CPython 3.12,
# x86-64), fetched here into .whl/ (kept out of git by .git/info/exclude): the versions of this
# checkout's own environment where it has them.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .git/info .whl
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo '/.whl/' >> .git/info/exclude
python=${PYTHON:-.venv/bin/python}
platforms=""
for p in manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_24_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64; do
    platforms="$platforms --platform $p"
done
for name in pyopencl pytools platformdirs siphash24 OpenEXR trimesh grimp import-linter; do
    version=$("$python" -m pip show "$name" 2>/dev/null | sed -n 's/^Version: //p')
    "$python" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        $platforms -d .whl "$name${version:+==$version}"
done
ls .whl
