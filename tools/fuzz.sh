#!/usr/bin/env bash
# Builds the libFuzzer targets with clang in build-fuzz/ and runs each for SECONDS (default 60) on
# a copy of its seed corpus. Fails (exit 1) on a crash, leak, timeout or out-of-memory and prints
# the path of the input that caused it. docs/hostile-input.md has the long run.
#
# Usage: tools/fuzz.sh [SECONDS]
#   U3MSCAN_FUZZ_BUILD_DIR  build folder (default build-fuzz)
#   U3MSCAN_FUZZ_TARGETS    space-separated subset of: fuzz_manifest fuzz_u3m_json fuzz_u3ma
#   U3MSCAN_FUZZ_ARGS       extra libFuzzer flags, e.g. "-jobs=4 -workers=4" or "-max_len=65536"
#   U3MSCAN_FUZZ_CXX        the clang++ to use (default: clang++, Debian's clang that install-deps.sh installs
#                           together with the matching libomp and libclang-rt)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
case "$seconds" in ''|*[!0-9]*) echo "usage: tools/fuzz.sh [SECONDS]" >&2; exit 2 ;; esac
build_dir=${U3MSCAN_FUZZ_BUILD_DIR:-build-fuzz}
targets=(${U3MSCAN_FUZZ_TARGETS:-fuzz_manifest fuzz_u3m_json fuzz_u3ma})
extra_args=(${U3MSCAN_FUZZ_ARGS:-})
source_dir=$PWD
export CCACHE_BASEDIR="$PWD"

# Debian's default clang: the one whose libomp and sanitizer runtimes install-deps.sh installs (a
# newer clang-NN installed by hand may lack them and fail to link).
cxx=${U3MSCAN_FUZZ_CXX:-clang++}
cc=${cxx/clang++/clang}
for tool in "$cc" "$cxx"; do
  command -v "$tool" >/dev/null || { echo "fuzz: $tool not found (tools/install-deps.sh installs clang)" >&2; exit 2; }
done

# -O1 with assertions on (no NDEBUG): sanitizers and assert()s both watch the parsers.
# A build dir configured with another compiler is configured anew.
if [ -f "$build_dir/CMakeCache.txt" ] && ! grep -q "^CMAKE_CXX_COMPILER:[A-Z]*=.*/$cxx\$" "$build_dir/CMakeCache.txt"; then
  rm -f "$build_dir/CMakeCache.txt"
  rm -rf "$build_dir/CMakeFiles"
fi
if [ ! -f "$build_dir/CMakeCache.txt" ]; then
  CC=$cc CXX=$cxx cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g" \
    -DU3MSCAN_BUILD_FUZZERS=ON -DU3MSCAN_BUILD_TESTS=ON >/dev/null
fi
cmake --build "$build_dir" -j "$(nproc)" --target "${targets[@]}"

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:symbolize=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

status=0
for target in "${targets[@]}"; do
  exe=$build_dir/tests/fuzz/$target
  corpus_name=${target#fuzz_}
  seeds=$source_dir/tests/fuzz/corpus/$corpus_name
  regressions=$source_dir/tests/fuzz/regressions/$corpus_name
  work=$build_dir/fuzz-run/$target
  mkdir -p "$work/corpus" "$work/artifacts"
  rm -f "$work"/artifacts/*
  # The copy grows as libFuzzer finds new paths and is kept for the next run; the seeds in the
  # source tree are never written.
  cp -n "$seeds"/* "$work/corpus/" 2>/dev/null || true
  # The checked-in bad inputs of tests/hostile are seeds too: they reach the refusal paths.
  case "$corpus_name" in
    manifest) hostile=$source_dir/tests/hostile/manifest ;;
    u3m_json) hostile=$source_dir/tests/hostile/u3m ;;
    u3ma) hostile=$source_dir/tests/hostile/u3ma ;;
    *) hostile= ;;
  esac
  [ -n "$hostile" ] && [ -d "$hostile" ] && for f in "$hostile"/*; do cp -n "$f" "$work/corpus/hostile_$(basename "$f")"; done
  dict_args=()
  [ -f "$source_dir/tests/fuzz/$corpus_name.dict" ] && dict_args=(-dict="$source_dir/tests/fuzz/$corpus_name.dict")
  log=$work/fuzz.log
  echo "fuzz: $target for ${seconds}s (corpus $work/corpus, log $log)"
  # Known bad inputs first: each must still be refused cleanly.
  if [ -d "$regressions" ] && [ -n "$(ls -A "$regressions" 2>/dev/null)" ]; then
    if ! "$exe" -artifact_prefix="$work/artifacts/" "$regressions"/* >"$work/regressions.log" 2>&1; then
      echo "fuzz: $target FAILED on a checked-in regression input (log $work/regressions.log):" >&2
      grep -E "^Running: |SUMMARY" "$work/regressions.log" | tail -n 3 >&2 || true
      status=1
      continue
    fi
  fi
  set +e
  "$exe" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$work/artifacts/" "${dict_args[@]}" "${extra_args[@]}" "$work/corpus" >"$log" 2>&1
  rc=$?
  set -e
  if [ $rc -ne 0 ]; then
    status=1
    echo "fuzz: $target FAILED (exit $rc); log $log" >&2
    grep -E "^==[0-9]+==ERROR|SUMMARY|runtime error|deadly signal|timeout after" "$log" | head -n 5 >&2 || true
    for artifact in "$work"/artifacts/*; do
      [ -e "$artifact" ] && echo "fuzz: crashing input: $artifact (reproduce: $exe $artifact)" >&2
    done
  else
    grep -E "^stat::number_of_executed_units|^stat::peak_rss_mb" "$log" | sed "s/^/fuzz: $target /"
  fi
done
exit $status
