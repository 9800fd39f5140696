#!/usr/bin/env bash
# Configures (once) and builds u3mscan in build/ with ccache. Usage: tools/build.sh [cmake --build args]
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${U3MSCAN_BUILD_DIR:-build}
# Paths relative to the checkout in ccache's hashes: a fresh clone elsewhere reuses the cache.
export CCACHE_BASEDIR="$PWD"
if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
fi
cmake --build "$build_dir" -j "$(nproc)" "$@"
