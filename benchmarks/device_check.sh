#!/usr/bin/env bash
# The device check (benchmarks/device_check.py) on a lent GPU machine, or here with --device cpu.
# On the lent machine it first unpacks what benchmarks/device_pack.sh staged and earlier calls
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
  if [ -f "$STAGED/parts.txt" ] && [ ! -f "$STAGED/unpacked" ]; then
    for part in $(cat "$STAGED/parts.txt"); do
      [ -f "$STAGED/$part" ] || { echo "device_check: $STAGED/$part has not been carried yet" >&2; exit 2; }
    done
    (cd "$STAGED" && cat $(cat parts.txt) | xz -dc | tar xf -)
    # kadv itself, so that its configs (kadv.conf) and its pytest plugin are found as when installed
    $PYTHON -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --no-build-isolation \
      --target "$STAGED/kadv" .
    touch "$STAGED/unpacked"
  fi
  export PYTHONPATH=$STAGED/kadv:$STAGED/site${PYTHONPATH:+:$PYTHONPATH}
  export LD_LIBRARY_PATH="$STAGED/syslibs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  export KADV_TEST_SCENES="$STAGED/scene"
fi
exec $PYTHON benchmarks/device_check.py "$@"
