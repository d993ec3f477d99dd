#!/usr/bin/env bash
# Installs tofcam from a build tree into a scratch prefix and builds a consumer project that uses
# find_package(tofcam). Usage: consumer_test.sh <build-dir> <source-dir>
set -euo pipefail
build=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
cmake -S "$src/tests/consumer" -B "$work/build" -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/build" -j 2 >/dev/null
"$work/build/consumer"

# The installed Python package imports from the prefix alone (not from the build tree).
pydir=$(sed -n 's/^TOFCAM_PYTHON_INSTALL_DIR:[A-Z]*=//p' "$build/CMakeCache.txt")
if [ -n "$pydir" ]; then
  python=$(sed -n 's/^TOFCAM_PYTHON_EXECUTABLE:[A-Z]*=//p' "$build/CMakeCache.txt")
  test -f "$work/prefix/$pydir/tofcam/__init__.py"
  (cd "$work" && PYTHONPATH="$work/prefix/$pydir" "$python" -c \
    "import tofcam, sys; assert tofcam.__file__.startswith('$work/prefix'), tofcam.__file__; \
     f = tofcam.SimulatedCamera('wall', supersampling=1).grab(); print('python', tofcam.__version__, f.distance.shape)")
fi
