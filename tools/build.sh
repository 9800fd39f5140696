#!/usr/bin/env bash
# Configures (once) and builds u3mscan in build/ with ccache. Usage: tools/build.sh [cmake --build args]
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${U3MSCAN_BUILD_DIR:-build}
if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build "$build_dir" -j "$(nproc)" "$@"
