#!/usr/bin/env bash
# The whole test suite built with AddressSanitizer and UndefinedBehaviorSanitizer, in build-asan/.
# Any memory error, leak or undefined behaviour in library, CLI or test code fails the test that
# hit it. Extra arguments go to ctest, e.g. `bash scripts/sanitize.sh -R 'test_mesh_io'`.
#
# install_consumer is left out: it links a separate, uninstrumented project against the
# instrumented library, which the sanitizer runtime refuses to load.
#
# `bash scripts/sanitize.sh --subset [CTEST ARGS]` also leaves out the tests that take 15 s or
# more each under the sanitizers on 2 cores (1,210 of the suite's 1,710 test-seconds): the
# exactness sweep over the shared meshes at 512 and the largest solid, tiling, round-trip and
# distance comparisons. Their code paths (loaders, binning, batches, solid, SDF, meshing) run in
# the smaller tests that stay, the CLI tests included.
#
# `bash scripts/sanitize.sh --ci` is the part CI runs (after the plain suite), sized for its time
# budget: it builds only the library, the CLI and the tests of what takes input from outside —
# the mesh and field readers (with the fuzzers' regression files), the writers, the host memory
# guards — and runs those with the CLI's fault tests (full disk, signals, concurrent writers,
# injected device faults). That is where hostile files and interrupted runs reach the code.
set -euo pipefail
cd "$(dirname "$0")/.."
exclude='^install_consumer$'
targets=()
optimization="-O1"
case "${1:-}" in
--subset)
    shift
    exclude+='|^SharedMeshes/EveryMesh\.|^Solid\.(OpenScanMatchesExactWindingNumber|'
    exclude+='ParityMatchesNaiveDoubleParityAwayFromTies|HierarchicalWindingStaysWithinItsErrorBound|'
    exclude+='InwardFacingMeshFillsLikeItsFlippedCopy|WindingDeviceMatchesDoubleReference)$|'
    exclude+='^Tiling\.(GridLargerThanDeviceBudget|HugeTriangleIsSpreadAndCulled)$|'
    exclude+='^RoundTrip\.(Spot|Sphere)MeshesStayWithinOneVoxel|'
    exclude+='^FieldMeshes\.RealMeshFields|^Sdf\.RealMeshMatchesDoubleBruteForce'
    ;;
--ci)
    shift
    targets=(--target oclvox_cli test_mesh_io test_field_io test_writers test_host_memory)
    # -O0 compiles 2.4 times faster than -O1 (OpenVDB's headers above all); these tests are
    # light enough that running slower costs less than that.
    optimization="-O0"
    # The tests of executables not built are placeholders named *_NOT_BUILT.
    exclude+='|_NOT_BUILT$|^cli_behaviour$'
    ;;
esac
bash scripts/install_deps.sh

flags="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="$optimization -g" \
  -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
  -DOCLVOX_BUILD_TESTS=ON -DOCLVOX_BUILD_BENCH=OFF "${launcher[@]}" >/dev/null
cmake --build build-asan -j"$(nproc)" "${targets[@]}"

# The OpenCL runtime (PoCL and the LLVM it loads) is not instrumented and keeps some allocations
# for the life of the process; scripts/lsan.supp names those libraries, and only those.
# Every report is also written to a file in build-asan/sanitizer-reports/: a report from a process
# whose failure a test expects (the CLI exiting 1 on bad input, after printing its error) must
# not pass as that failure.
reports="$PWD/build-asan/sanitizer-reports"
rm -rf "$reports" && mkdir -p "$reports"
# use_sigaltstack=0: on some kernels (seen on a 6.18 VM) ASan cannot unmap a finished thread's
# alternate signal stack and aborts the process ("unable to unmap", exit 1 with no output); a
# stack overflow then still crashes its test, reported as a plain SIGSEGV.
export ASAN_OPTIONS="use_sigaltstack=0:detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=1:log_path=$reports/asan"
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:log_path=$reports/ubsan"
status=0
(cd build-asan && ctest --output-on-failure -j"$(nproc)" --timeout 1800 -E "$exclude" "$@") ||
    status=$?
# LeakSanitizer's own tracer can crash while it stops a process's threads at exit ("Tracer caught
# signal 11 ... LeakSanitizer has encountered a fatal error", seen once in a CI run whose tests all
# passed): that process's leaks went unchecked, which is printed, but it is not a finding.
findings=0
if [ -n "$(ls -A "$reports")" ]; then
    echo "sanitizer reports (build-asan/sanitizer-reports):"
    for report in "$reports"/*; do
        echo "--- $report"
        cat "$report"
        if grep -q "LeakSanitizer has encountered a fatal error" "$report" &&
            ! grep -qE "ERROR: (AddressSanitizer|LeakSanitizer: detected)|runtime error" "$report"; then
            echo "(the leak checker itself failed in this process: its leaks went unchecked)"
        else
            findings=1
        fi
    done
fi
[ "$findings" = 0 ] || exit 1
exit "$status"
