#!/bin/bash
# The wheels bench/device_check.sh installs on a machine that reaches no registry (CPython 3.12,
# x86-64), fetched here into .whl/ (kept out of git by the repository's info/exclude): the versions of this
# checkout's own environment where it has them.
set -euo pipefail
cd "$(dirname "$0")/.."
exclude=$(git rev-parse --git-path info/exclude)  # (a worktree's is its repository's)
mkdir -p "$(dirname "$exclude")" .whl
grep -qx '/.whl/' "$exclude" 2>/dev/null || echo '/.whl/' >> "$exclude"
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
# NVIDIA Warp (bench/gpu_warp.py) for a CPython 3.12 x86-64 machine: its wheel (about 150 MB) exceeds what
# one call may carry, so its package, less what a GPU run does not load (warp-clang.so, its CPU
# compiler; the examples), is packed as one xz tarball (81 MB for 1.19.0) in parts of PART_MB (45) under .warp/ (ignored like
# .whl/), each carried by one call (bench/device_check.sh stage), with the tarball's sha256
warp=${WARP_VERSION:-$("$python" -m pip show warp-lang 2>/dev/null | sed -n 's/^Version: //p')}
grep -qx '/.warp/' "$exclude" 2>/dev/null || echo '/.warp/' >> "$exclude"
tmp=$(mktemp -d)
"$python" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    $platforms -d "$tmp" "warp-lang${warp:+==$warp}"
(cd "$tmp" && "$python" -m zipfile -e warp_lang-*.whl site && rm -rf site/warp/bin/warp-clang.so site/warp/examples)
rm -rf .warp && mkdir -p .warp
tar -C "$tmp/site" -cf - warp "$(cd "$tmp/site" && ls -d warp_lang-*.dist-info)" | xz -T2 -6 > "$tmp/warp.tar.xz"
(cd "$tmp" && sha256sum warp.tar.xz) > .warp/warp.tar.xz.sha256
split -b "${PART_MB:-45}M" -d -a 2 "$tmp/warp.tar.xz" .warp/warp.tar.xz.part
rm -rf "$tmp"
ls -la .warp
