#!/usr/bin/env bash
# Stage what a lent GPU machine lacks, in parts that each fit one call's 64 MiB (docs/performance.md,
# "On a lent GPU"): the wheels of kadv's dependencies that its image does not hold (Python 3.12,
# manylinux x86-64), split into pieces, and the shared grey_white_room (the benchmark's scene). Run here, where PyPI answers:
#
#   bash benchmarks/device_pack.sh            # writes .device/carry1 .. .device/carryN (git-ignored)
#
# Then carry .device/carry1 .. carryN in successive calls to one warm machine, each copying its part
# to /tmp/kadv-device, and run benchmarks/device_check.sh there in the last.
set -euo pipefail
cd "$(dirname "$0")/.."
PART_MIB=${PART_MIB:-48}   # the working tree travels with each part: about 11 MiB of it
SCENES=${KADV_TEST_SCENES:-$(cd .. && pwd)/shared/scenes}
# the packages kadv imports that the GPU image lacks, at the versions this checkout runs
PACKAGES="warp-lang open3d-cpu kornia kornia-rs trimesh hydra-core omegaconf hydra-joblib-launcher
hydra-submitit-launcher submitit cma nevergrad bayesian-optimization directsearch"
PYTHON=${PYTHON:-.venv/bin/python}
rm -rf .device && mkdir -p .device/wheels .device/stage/scene
pins=$($PYTHON -m pip list --format=freeze 2>/dev/null | tr 'A-Z_' 'a-z-')
for package in $PACKAGES; do
  pin=$(echo "$pins" | grep -E "^${package}==" || true)
  [ -n "$pin" ] || { echo "device_pack: $package is not installed in $PYTHON's environment" >&2; exit 2; }
  $PYTHON -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_35_x86_64 --platform manylinux_2_34_x86_64 --platform manylinux_2_28_x86_64 \
    --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .device/wheels "$pin" 2>/dev/null
done
# omegaconf's parser runtime is published as a source archive only: built here into a pure-Python wheel
antlr=$(echo "$pins" | grep -E "^antlr4-python3-runtime==")
$PYTHON -m pip wheel --quiet --no-deps -w .device/wheels "$antlr" 2>/dev/null
mkdir -p .device/stage/scene/grey_white_room
cp -r "$SCENES/grey_white_room/scene.xml" "$SCENES/grey_white_room/models" "$SCENES/grey_white_room/textures" \
  .device/stage/scene/grey_white_room/
# the system libraries Open3D's CPU build links (EGL, GL, X11, udev, usb: the GPU image lacks
# libEGL), all of them built for glibc 2.34 or older
mkdir -p .device/stage/syslibs
open3d=$($PYTHON -c "import os, open3d; print(os.path.dirname(open3d.__file__))")
for lib in $(ldd "$open3d"/pybind*.so | awk '$3 ~ /^\/(usr\/)?lib/ {print $3}'); do
  case $(basename "$lib") in
    libc.so*|libm.so*|libstdc++*|libgcc_s*|ld-linux*|libpthread*|libdl.so*|librt.so*) ;;
    *) cp -L "$lib" .device/stage/syslibs/ ;;
  esac
done
(cd .device/wheels && tar cf ../stage/wheels.tar ./*.whl)
(cd .device/stage && tar cf - wheels.tar scene syslibs | split -b "${PART_MIB}m" -d -a 2 - ../part.)
count=0
for part in .device/part.*; do
  count=$((count + 1))
  mkdir -p ".device/carry$count" && mv "$part" ".device/carry$count/"
done
# the last carry names every part, so the check knows when all have come
(cd .device && for carry in carry*; do ls "$carry"; done | grep "^part\." | sort > parts.txt && mv parts.txt "carry$count/")
rm -rf .device/wheels .device/stage
echo "device_pack: $(ls .device/carry*/part.* | wc -l) parts in $count carries (.device/carry1 .. carry$count)"
