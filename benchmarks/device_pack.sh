#!/usr/bin/env bash
# Stage what a lent GPU machine lacks, in at most 4 parts that each fit one call's 64 MiB beside the
# working tree (docs/performance.md, "On a lent GPU"): the packages kadv imports that the GPU image
# does not hold, installed here for Python 3.12 (manylinux x86-64) and stripped of what kadv never
# loads (Open3D's GUI resources and TensorFlow/PyTorch ops, Warp's examples and tests), the system
# libraries Open3D's CPU build links, and the shared grey_white_room (the benchmark's scene), as one
# xz stream cut into parts. Run here, where PyPI answers:
#
#   bash benchmarks/device_pack.sh            # writes .device/carry1 .. .device/carryN (git-ignored)
#
# Then carry .device/carry1 .. carryN in successive calls to one warm machine, each copying its part
# to /tmp/kadv-device, and run benchmarks/device_check.sh there in the last.
set -euo pipefail
cd "$(dirname "$0")/.."
PART_MIB=${PART_MIB:-52}   # the working tree (about 11 MiB) travels with each part
MAX_PARTS=4
SCENES=${KADV_TEST_SCENES:-$(cd .. && pwd)/shared/scenes}
# the packages kadv imports that the GPU image lacks, at the versions this checkout runs
PACKAGES="warp-lang open3d-cpu kornia kornia-rs trimesh hydra-core omegaconf hydra-joblib-launcher
hydra-submitit-launcher submitit cma nevergrad bayesian-optimization directsearch"
PYTHON=${PYTHON:-.venv/bin/python}
rm -rf .device && mkdir -p .device/wheels .device/stage/site .device/stage/scene .device/stage/syslibs
pins=$($PYTHON -m pip list --format=freeze 2>/dev/null | tr 'A-Z_' 'a-z-')
wanted=()
for package in $PACKAGES; do
  pin=$(echo "$pins" | grep -E "^${package}==" || true)
  [ -n "$pin" ] || { echo "device_pack: $package is not installed in $PYTHON's environment" >&2; exit 2; }
  wanted+=("$pin")
done
# installed, not carried as wheels: the GPU machine then unpacks and runs, with no pip step
$PYTHON -m pip install --quiet --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_35_x86_64 --platform manylinux_2_34_x86_64 --platform manylinux_2_28_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --target .device/stage/site "${wanted[@]}"
# omegaconf's parser runtime is published as a source archive only: built here into a pure-Python wheel
antlr=$(echo "$pins" | grep -E "^antlr4-python3-runtime==")
$PYTHON -m pip wheel --quiet --no-deps -w .device/wheels "$antlr" 2>/dev/null
$PYTHON -m pip install --quiet --no-deps --target .device/stage/site .device/wheels/*.whl
site=.device/stage/site
rm -rf "$site"/open3d/{resources,examples,_ml3d,open3d_tf_ops.so,open3d_torch_ops.so} \
  "$site"/warp/{examples,tests} "$site"/bin
# Open3D's Plotly viewer needs dash, which the image lacks and kadv never calls
sed -i 's/^from .draw_plotly import/# &/' "$site"/open3d/visualization/__init__.py
mkdir -p .device/stage/scene/grey_white_room
cp -r "$SCENES/grey_white_room/scene.xml" "$SCENES/grey_white_room/models" "$SCENES/grey_white_room/textures" \
  .device/stage/scene/grey_white_room/
# the system libraries Open3D's CPU build links (EGL, GL, X11, udev, usb: the GPU image lacks
# libEGL), all of them built for glibc 2.34 or older
open3d=$($PYTHON -c "import os, open3d; print(os.path.dirname(open3d.__file__))")
for lib in $(ldd "$open3d"/pybind*.so | awk '$3 ~ /^\/(usr\/)?lib/ {print $3}'); do
  case $(basename "$lib") in
    libc.so*|libm.so*|libstdc++*|libgcc_s*|ld-linux*|libpthread*|libdl.so*|librt.so*) ;;
    *) cp -L "$lib" .device/stage/syslibs/ ;;
  esac
done
(cd .device/stage && tar cf - site scene syslibs | xz -T0 -6 | split -b "${PART_MIB}m" -d -a 2 - ../part.)
rm -rf .device/wheels .device/stage
count=0
for part in .device/part.*; do
  count=$((count + 1))
  mkdir -p ".device/carry$count" && mv "$part" ".device/carry$count/"
done
[ "$count" -le "$MAX_PARTS" ] || { echo "device_pack: $count parts, more than $MAX_PARTS calls" >&2; exit 1; }
# the last carry names every part, so the check knows when all have come
(cd .device && for carry in carry*; do ls "$carry"; done | grep "^part\." | sort > parts.txt && mv parts.txt "carry$count/")
echo "device_pack: $count parts of at most $PART_MIB MiB in .device/carry1 .. carry$count ($(du -sm .device | cut -f1) MiB)"
