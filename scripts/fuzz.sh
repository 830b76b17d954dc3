#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ in build-fuzz/ (clang, -fsanitize=fuzzer,address,undefined)
# and runs each for SECONDS, starting from the seed corpus fuzz/corpus/<target>/ with the
# dictionary fuzz/dict/<target>.dict. Prints libFuzzer's summary line for every target and exits
# non-zero if any target found a crash, leak, timeout, oversized allocation or sanitizer report;
# the input that triggered it is kept in build-fuzz/artifacts/<target>/.
#
#   bash scripts/fuzz.sh SECONDS [TARGET...]     (default: every target)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:?usage: scripts/fuzz.sh SECONDS [TARGET...]}
shift
bash scripts/install_deps.sh --fuzz

# Phase 1: build. The library is instrumented for coverage and sanitizers; only the targets link
# libFuzzer's main.
flags="-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" -DCMAKE_CXX_FLAGS="$flags" \
  -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DOCLVOX_BUILD_FUZZERS=ON -DOCLVOX_BUILD_TESTS=OFF -DOCLVOX_BUILD_CLI=OFF \
  -DOCLVOX_BUILD_BENCH=OFF "${launcher[@]}" >/dev/null
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for dir in fuzz/corpus/*/; do targets+=("$(basename "$dir")"); done
fi
cmake --build build-fuzz -j"$(nproc)" --target "${targets[@]}"

# Phase 2: run. New inputs go to build-fuzz/corpus/<target>/, never into the repository's seeds.
# Limits: an input may use at most 2 GiB in all and 1 GiB in one allocation, and run at most 10 s;
# more is reported as a bug (inputs are a few KiB at most).
export ASAN_OPTIONS="use_sigaltstack=0:detect_leaks=1:strict_string_checks=1"  # see sanitize.sh
export UBSAN_OPTIONS="print_stacktrace=1"
root=$PWD
failed=()
for target in "${targets[@]}"; do
  work=build-fuzz/corpus/$target artifacts=build-fuzz/artifacts/$target
  log=build-fuzz/$target.log
  mkdir -p "$work" "$artifacts"
  dict=()
  [ -f "fuzz/dict/$target.dict" ] && dict=(-dict="$root/fuzz/dict/$target.dict")
  status=0
  (cd build-fuzz && TMPDIR="$PWD" "./fuzz/$target" "${dict[@]}" \
     -max_total_time="$seconds" -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=10 \
     -print_final_stats=1 -artifact_prefix="artifacts/$target/" \
     "corpus/$target" "../fuzz/corpus/$target") >"$log" 2>&1 || status=$?
  runs=$(grep -E '^(Done [0-9]+ runs|stat::number_of_executed_units)' "$log" | head -1 || true)
  if [ "$status" -eq 0 ]; then
    echo "$target: ok: $runs"
  else
    echo "$target: FAILED (exit $status): $runs"
    grep -E 'ERROR: (libFuzzer|AddressSanitizer|LeakSanitizer)|runtime error|SUMMARY|Test unit written' \
      "$log" | head -8 | sed 's/^/    /'
    echo "    full log: $log"
    failed+=("$target")
  fi
done
[ ${#failed[@]} -eq 0 ] || { echo "fuzz: findings in ${failed[*]}"; exit 1; }
echo "fuzz: no findings in ${#targets[@]} targets, ${seconds} s each"
