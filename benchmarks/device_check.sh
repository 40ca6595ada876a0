#!/usr/bin/env bash
# The device check (benchmarks/device_check.py) on a lent GPU machine, or here with --device cpu.
# On the lent machine it first installs what benchmarks/device_pack.sh staged and earlier calls
# copied to /tmp/kadv-device (docs/performance.md, "On a lent GPU"); here it uses .venv.
#
#   bash benchmarks/device_check.sh --device cuda [--out DIR]
#   bash benchmarks/device_check.sh --device cpu
set -euo pipefail
cd "$(dirname "$0")/.."
STAGED=${KADV_DEVICE_STAGED:-/tmp/kadv-device}
if [ -x .venv/bin/python ]; then
  PYTHON=.venv/bin/python
else
  PYTHON=python3
  if [ -f "$STAGED/parts.txt" ] && [ ! -f "$STAGED/installed" ]; then
    for part in $(cat "$STAGED/parts.txt"); do
      [ -f "$STAGED/$part" ] || { echo "device_check: $STAGED/$part has not been carried yet" >&2; exit 2; }
    done
    (cd "$STAGED" && cat $(cat parts.txt) | tar xf - && tar xf wheels.tar)
    # the wheels, and kadv itself: its configs (kadv.conf) and its pytest plugin are then found as
    # when installed
    $PYTHON -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --no-build-isolation \
      --target /tmp/site "$STAGED"/*.whl .
    # Open3D's Plotly viewer needs dash, which the image lacks and kadv never calls
    sed -i 's/^from .draw_plotly import/# &/' /tmp/site/open3d/visualization/__init__.py
    touch "$STAGED/installed"
  fi
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
  [ -d "$STAGED/syslibs" ] && export LD_LIBRARY_PATH="$STAGED/syslibs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  [ -d "$STAGED/scene" ] && export KADV_TEST_SCENES="$STAGED/scene"
fi
exec $PYTHON benchmarks/device_check.py "$@"
