#!/usr/bin/env bash
# The checks a session with a lent GPU machine should run, prepared as one call (device time is
# short: every start, wait and rerun counts). Here, first:
#   bash scripts/build.sh -DOCLVOX_BUILD_TESTS=ON
#   PACK_MESHES="bunny00.off spot.obj stanford-bunny.obj buildings.obj motorBike.obj TR12J_OCC.stl \
#     flange.stl horse.ply mug.obj spot_quadrangulated.obj double-torus-example.off \
#     Sterngarten_Wien_innerArea.obj Sterngarten_Wien_innerArea.mtl" \
#     bash ../shared/tools/gpu/pack.sh build
#   bash scripts/gpu_python.sh pack   (optional: the Python and CLI shell tests, part 1b)
# Then with the device tool, from the repository root:
#   run(command="source .gpu/env.sh && bash scripts/gpu_check.sh", carry=[".gpu"], timeout_s=540)
# It writes under $OUT (the device tool brings it back):
#   tests.txt    each C++ test binary on the GPU (OCLVOX_DEVICE as env.sh set it): exit status and
#                gtest's summary; then the CLI's shell tests (their FAIL and SKIP lines) and pytest;
#                the whole output of a failing one in tests/NAME.log (only those: the device tool
#                brings back a limited number of files)
#   same.txt     surface, thin, parity and winding voxels and band SDFs of a few meshes on the GPU
#                and through PoCL (`OCLVOX_DEVICE=Portable`, the same machine's 16 cores): "same"
#                where the two files are byte-identical, as the kernels promise
#   GPU.md       bench/targets.py --set gpu: the whole-process targets of issues 8 and 9
# Each part has a time limit of its own, so one that hangs leaves the others their time.
set -uo pipefail
out=${OUT:-/tmp/oclvox-gpu-check}
mkdir -p "$out/tests"
meshes=$(dirname "$B")/meshes

# Part 1: the C++ test binaries.
: > "$out/tests.txt"
for test in "$B"/test_*; do
    name=$(basename "$test")
    log=$(mktemp)
    timeout 150 "$test" --gtest_brief=1 > "$log" 2>&1
    status=$?
    echo "$name exit $status: $(grep -E '^\[  (PASSED|FAILED)  \]' "$log" | tr '\n' ' ')" |
        tee -a "$out/tests.txt"
    if [[ $status == 0 ]]; then rm -f "$log"; else mv "$log" "$out/tests/$name.log"; fi
done

# Part 1b: where scripts/gpu_python.sh packed Python (.gpu/python.tar.xz), the Python package's
# tests and the CLI's shell tests (whose checks read files with numpy) on the GPU too.
if [[ -f .gpu/python.tar.xz ]]; then
    py=$(bash scripts/gpu_python.sh unpack)
    source_dir=$(sed -n 's/^source_dir=//p' "$(dirname "$B")/paths")
    for shell_test in cli_test fault_test; do
        log=$(mktemp)
        PATH=$py/bin:$PATH OCLVOX=$B/oclvox OCLVOX_MESH_DIR=$meshes \
            OCLVOX_SAMPLE_DIR=$source_dir/samples timeout 300 bash "tests/$shell_test.sh" > "$log" 2>&1
        status=$?
        echo "$shell_test exit $status: $(tail -n1 "$log")" | tee -a "$out/tests.txt"
        grep -E '^(FAIL|SKIP)' "$log" >> "$out/tests.txt"
        if [[ $status == 0 ]]; then rm -f "$log"; else mv "$log" "$out/tests/$shell_test.log"; fi
    done
    log=$(mktemp)
    timeout 300 bash scripts/gpu_python.sh run > "$log" 2>&1
    status=$?
    echo "pytest exit $status: $(tail -n1 "$log")" | tee -a "$out/tests.txt"
    if [[ $status == 0 ]]; then rm -f "$log"; else mv "$log" "$out/tests/pytest.log"; fi
fi

# Part 2: the GPU's voxels against PoCL's, byte for byte.
: > "$out/same.txt"
work=$(mktemp -d)
# `oclvox ARGS... -o FILE` on the GPU and through PoCL: "same" where the two files are equal.
same_as_pocl() {
    local label=$1 extension=$2
    shift 2
    timeout 60 "$B/oclvox" "$@" -o "$work/gpu.$extension" --quiet &&
        OCLVOX_DEVICE=Portable timeout 120 "$B/oclvox" "$@" -o "$work/pocl.$extension" --quiet &&
        cmp -s "$work/gpu.$extension" "$work/pocl.$extension"
    local status=$?
    echo "$label: $([[ $status == 0 ]] && echo same || echo DIFFERENT)" | tee -a "$out/same.txt"
}
for mesh in stanford-bunny.obj buildings.obj TR12J_OCC.stl bunny00.off; do
    [[ -f $meshes/$mesh ]] || continue
    for mode in "--test sat" "--test pef" "--mode thin" "--test sat --boundary half-open" \
        "--mode solid --inside parity"; do
        [[ $mode == *solid* && $mesh != bunny00.off ]] && continue  # parity needs a closed mesh
        # shellcheck disable=SC2086  # $mode is several words
        same_as_pocl "$mesh 700 $mode" binvox voxelize "$meshes/$mesh" -r 700 $mode
    done
done
# The winding-number solid and the band SDF promise the same bits too (on devices with correctly
# rounded division and sqrt, which NVIDIA's driver and PoCL have): open meshes at sizes where a
# voxel's |w| lies near 1/2 (the open scan at 512 had one voxel differ before the kernel's
# arithmetic was written out), and band SDFs as .npy.
for case in "stanford-bunny.obj 512" "Sterngarten_Wien_innerArea.obj 256" "mug.obj 200"; do
    read -r mesh resolution <<< "$case"
    [[ -f $meshes/$mesh ]] || continue
    same_as_pocl "$mesh $resolution --mode solid --inside winding" binvox voxelize \
        "$meshes/$mesh" -r "$resolution" --mode solid --inside winding
done
for mesh in bunny00.off buildings.obj; do
    [[ -f $meshes/$mesh ]] || continue
    same_as_pocl "$mesh 256 sdf --band 3" npy sdf "$meshes/$mesh" -r 256 --band 3
done
rm -rf "$work"

# Part 3: issue 8's and 9's GPU targets, whole processes.
timeout 300 python3 bench/targets.py --oclvox "$B/oclvox" --meshes "$meshes" --set gpu --repeat 3 \
    --out "$out/GPU.md"
