#!/usr/bin/env bash
# Faults the oclvox command-line tool must survive with a clear error, the right exit code and
# no output left behind (neither the final file nor a temporary one):
#  - a full disk while writing .binvox, .npy (+ sidecar), .vdb, .obj and .ply;
#  - SIGINT and SIGTERM during load, compute and write: stopped within 2 s, exit 130 / 143;
#  - two runs writing the same output at once: one complete file, never a mix;
#  - a kernel build failure (the build log is shown), device allocation failures (retried with
#    smaller batches, then a clear error), through the library's fault-injection variables.
# The full-disk part mounts a 2 MB tmpfs, which needs root; without it the test says so and ends
# with exit code 77 (reported by ctest as skipped), never as a silent pass.
#
# Environment: OCLVOX (the binary), OCLVOX_SAMPLE_DIR (holds spot.obj).
set -u

: "${OCLVOX:?set OCLVOX to the oclvox binary}"
: "${OCLVOX_SAMPLE_DIR:?set OCLVOX_SAMPLE_DIR to the folder holding spot.obj}"
MESH="$OCLVOX_SAMPLE_DIR/spot.obj"

WORK=$(mktemp -d)
DISK="$WORK/disk"
cleanup() {
    mountpoint -q "$DISK" 2>/dev/null && umount "$DISK"
    rm -rf "$WORK"
}
trap cleanup EXIT

source "$(dirname "${BASH_SOURCE[0]}")/shell_checks.sh"

run() {
    "$OCLVOX" "$@" >"$WORK/stdout" 2>"$WORK/stderr"
    RC=$?
    ERR=$(cat "$WORK/stderr")
}

# Files in a folder (names only), or nothing.
listing() { ls -A "$1" 2>/dev/null | tr '\n' ' '; }

# ---------------------------------------------------------------------------------------------
# Full disk: a 2 MB tmpfs, filled up to a few KiB, so every output below overflows it.
# ---------------------------------------------------------------------------------------------
mkdir -p "$DISK"
if mount_error=$(mount -t tmpfs -o size=2m tmpfs "$DISK" 2>&1); then
    head -c $((2048 * 1024 - 16 * 1024)) /dev/zero >"$DISK/filler" 2>/dev/null
    full_disk() {  # name, output file name, command...
        local name=$1 file=$2
        shift 2
        run "$@"
        local left
        left=$(listing "$DISK")
        if [ "$RC" -ne 1 ]; then
            fail "full disk, $name: exit code" "expected 1, got $RC: $ERR"
        elif ! grep -q "$DISK/$file" <<<"$ERR"; then
            fail "full disk, $name: the error names the file" "$ERR"
        elif [ "$left" != "filler " ]; then
            fail "full disk, $name: nothing left behind" "left: $left"
        else
            pass "full disk, $name: exit 1, names $file, nothing left"
        fi
    }
    full_disk ".binvox" out.binvox voxelize "$MESH" -r 96 --mode solid --reference -q \
        -o "$DISK/out.binvox"
    full_disk ".npy" out.npy voxelize "$MESH" -r 48 --reference -q -o "$DISK/out.npy"
    full_disk ".obj (voxel cubes)" out.obj voxelize "$MESH" -r 32 --reference -q \
        -o "$DISK/out.obj"
    full_disk ".vdb" out.vdb sdf "$MESH" -r 32 --reference -q -o "$DISK/out.vdb"
    full_disk ".npy field" field.npy sdf "$MESH" -r 32 --reference -q -o "$DISK/field.npy"
    full_disk ".ply mesh" out.ply mesh "$MESH" -r 32 --reference -q -o "$DISK/out.ply"
    # The array fits, its sidecar does not: both must go.
    rm -f "$DISK/filler"
    head -c $((2048 * 1024 - 16 * 1024)) /dev/zero >"$DISK/filler"
    full_disk ".npy whose sidecar does not fit" small.npy voxelize "$MESH" -r 24 --reference \
        -q --cubic -o "$DISK/small.npy"
    umount "$DISK"
else
    skip "full disk: cannot mount a 2 MB tmpfs at $DISK (needs root): $mount_error"
fi

# ---------------------------------------------------------------------------------------------
# Signals. A FIFO as input keeps the run in the load phase; a large reference run keeps it
# computing; a large .npy keeps it writing (the signal is sent the moment its temporary file
# appears, with the process stopped meanwhile so the write cannot finish first).
# ---------------------------------------------------------------------------------------------
mkfifo "$WORK/never.obj"
signal_test() {  # phase, signal name, output, command...
    local phase=$1 signal=$2 output=$3
    shift 3
    local folder
    folder=$(dirname "$output")
    rm -rf "$folder" && mkdir -p "$folder"
    local result
    result=$(python3 - "$phase" "$signal" "$folder" "$OCLVOX" "$@" <<'PY'
import os, signal, subprocess, sys, time
phase, name, folder, command = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
number = getattr(signal, name)
process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
start = time.monotonic()
if phase == "write":
    # Poll for the temporary file, then stop the process before sending the signal, so that the
    # signal lands while the file is being written.
    while process.poll() is None and not any(".tmp-" in n for n in os.listdir(folder)):
        if time.monotonic() - start > 60:
            break
        time.sleep(0.0005)
    if process.poll() is None:
        process.send_signal(signal.SIGSTOP)
        sent = time.monotonic()
        process.send_signal(number)
        process.send_signal(signal.SIGCONT)
else:
    time.sleep(1.5)
    sent = time.monotonic()
    process.send_signal(number)
if process.poll() is not None and phase == "write" and "sent" not in dir():
    print("finished before the signal could be sent: exit %d" % process.returncode)
    sys.exit()
try:
    code = process.wait(timeout=10)
except subprocess.TimeoutExpired:
    process.kill()
    print("still running 10 s after the signal")
    sys.exit()
took = time.monotonic() - sent
left = sorted(os.listdir(folder))
print("exit %d after %.2f s, left: %s, stderr: %s" % (code, took, " ".join(left) or "nothing",
      process.stderr.read().decode().strip().replace("\n", " | ")))
PY
)
    local expected=130
    [ "$signal" = SIGTERM ] && expected=143
    if [[ "$result" =~ ^exit\ $expected\ after\ (0|1)\.[0-9]+\ s,\ left:\ nothing ]]; then
        pass "$signal during $phase: ${result%%, stderr*}"
    else
        fail "$signal during $phase: expected exit $expected within 2 s and nothing left" "$result"
    fi
}
for sig in SIGINT SIGTERM; do
    signal_test load "$sig" "$WORK/signal/out.binvox" voxelize "$WORK/never.obj" -r 32 -q \
        -o "$WORK/signal/out.binvox"
    signal_test compute "$sig" "$WORK/signal/out.binvox" voxelize "$MESH" -r 2048 --mode solid \
        --reference -q -o "$WORK/signal/out.binvox"
    signal_test write "$sig" "$WORK/signal/out.npy" voxelize "$MESH" -r 640 --reference -q \
        -o "$WORK/signal/out.npy"
done

# ---------------------------------------------------------------------------------------------
# Two runs writing the same file at once: the file is one of the two complete results.
# ---------------------------------------------------------------------------------------------
mkdir -p "$WORK/race"
"$OCLVOX" voxelize "$MESH" -r 200 --reference -q -o "$WORK/race/a.binvox" &&
    "$OCLVOX" voxelize "$MESH" -r 201 --reference -q -o "$WORK/race/b.binvox"
race_ok=1
for attempt in 1 2 3; do
    "$OCLVOX" voxelize "$MESH" -r 200 --reference -q -o "$WORK/race/out.binvox" &
    first=$!
    "$OCLVOX" voxelize "$MESH" -r 201 --reference -q -o "$WORK/race/out.binvox"
    second=$?
    wait "$first"
    if [ $? -ne 0 ] || [ "$second" -ne 0 ]; then
        race_ok=0 && fail "concurrent writers: both runs succeed" "attempt $attempt" && break
    fi
    if ! cmp -s "$WORK/race/out.binvox" "$WORK/race/a.binvox" &&
        ! cmp -s "$WORK/race/out.binvox" "$WORK/race/b.binvox"; then
        race_ok=0 && fail "concurrent writers: the file is one complete result" \
            "attempt $attempt: matches neither run" && break
    fi
    left=$(listing "$WORK/race")
    if [ "$left" != "a.binvox b.binvox out.binvox " ]; then
        race_ok=0 && fail "concurrent writers: no temporary file left" "left: $left" && break
    fi
done
[ "$race_ok" -eq 1 ] && pass "concurrent writers: 3 races, each left one complete file"

# ---------------------------------------------------------------------------------------------
# Device faults, injected through the library's test variables.
# ---------------------------------------------------------------------------------------------
mkdir -p "$WORK/device"
OCLVOX_FAULT_BUILD_OPTIONS="-Dfloat=no_such_type" run voxelize "$MESH" -r 32 -q \
    -o "$WORK/device/out.binvox"
if [ "$RC" -eq 1 ] && grep -q "build log" <<<"$ERR" && grep -q "no_such_type" <<<"$ERR" &&
    [ -z "$(listing "$WORK/device")" ]; then
    pass "kernel build failure: exit 1, the compiler's log is shown, no output"
else
    fail "kernel build failure: exit 1, the compiler's log is shown, no output" \
        "exit $RC, left: $(listing "$WORK/device"), stderr: ${ERR:0:300}"
fi

# Bricks of 128^3 voxels need 256 KiB of bits each: with device buffers limited to 1 MiB the
# first batch (every active brick) fails and is retried smaller until it fits. The result must be
# the CPU reference's, bit for bit, and the summary must say that batches were retried.
"$OCLVOX" voxelize "$MESH" -r 256 --brick-size 128 --reference -q -o "$WORK/device/expected.binvox"
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=1 run voxelize "$MESH" -r 256 --brick-size 128 \
    -o "$WORK/device/retried.binvox"
if [ "$RC" -eq 0 ] && grep -q "batches retried smaller" "$WORK/stdout" &&
    cmp -s "$WORK/device/retried.binvox" "$WORK/device/expected.binvox"; then
    pass "device allocation failure: retried with smaller batches, said so, same voxels"
else
    fail "device allocation failure: retried with smaller batches, said so, same voxels" \
        "exit $RC, stdout: $(cat "$WORK/stdout"), stderr: ${ERR:0:300}"
fi
rm -f "$WORK/device/retried.binvox"

# The solid and the signed distance take the same retries: parity's brick columns (each 512 KiB
# of bits and 512 KiB of bricks here; all of them fail, half of them fit), the winding number's
# points (batches over 4 KiB fail) and the parity solid that signs a distance field. Each result
# must equal the one made without faults (parity: the CPU reference; the winding number and the
# distances: the device without faults, since both evaluate each voxel alone, whatever the batch).
# The narrow-band sdf is sparse: its batches of leaves are retried too.
retried() {  # name, expected file, result file, command...
    local name=$1 expected=$2 result=$3
    shift 3
    run "$@"
    if [ "$RC" -eq 0 ] && grep -q "batches retried smaller" "$WORK/stdout" &&
        cmp -s "$result" "$expected"; then
        pass "device allocation failure, $name: retried with smaller batches, said so, same result"
    else
        fail "device allocation failure, $name: retried with smaller batches, said so, same result" \
            "exit $RC, stdout: $(cat "$WORK/stdout"), stderr: ${ERR:0:300}"
    fi
    rm -f "$result" "$expected" "$expected.json" "$result.json"
}
"$OCLVOX" voxelize "$MESH" -r 256 --brick-size 128 --mode solid --reference -q \
    -o "$WORK/device/expected.binvox"
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=1 retried "parity solid" "$WORK/device/expected.binvox" \
    "$WORK/device/retried.binvox" voxelize "$MESH" -r 256 --brick-size 128 --mode solid \
    -o "$WORK/device/retried.binvox"
"$OCLVOX" voxelize "$MESH" -r 128 --mode solid --inside winding -q \
    -o "$WORK/device/expected.binvox"
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=0.004 retried "winding-number solid" \
    "$WORK/device/expected.binvox" "$WORK/device/retried.binvox" voxelize "$MESH" -r 128 \
    --mode solid --inside winding -o "$WORK/device/retried.binvox"
"$OCLVOX" sdf "$MESH" -r 128 -q -o "$WORK/device/expected.npy"
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=0.25 retried "sdf sign and leaves" "$WORK/device/expected.npy" \
    "$WORK/device/retried.npy" sdf "$MESH" -r 128 -o "$WORK/device/retried.npy"
# csg computes two distance fields: its count is the sum of both (here the same mesh twice on the
# same grid, so twice the sdf's; both sparse, retrying their signs' and their leaves' batches).
retries() {  # command... (prints allocation_retries of its --json summary)
    OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=0.1 "$OCLVOX" "$@" --json 2>/dev/null |
        python3 -c 'import json, sys; print(json.load(sys.stdin)["allocation_retries"])'
}
sdf_retries=$(retries sdf "$MESH" -r 96 -o "$WORK/device/one.npy")
csg_retries=$(retries csg "$MESH" union "$MESH" -r 96 -o "$WORK/device/two.npy")
if [ -n "$sdf_retries" ] && [ "$sdf_retries" -gt 0 ] && [ "$csg_retries" = $((2 * sdf_retries)) ]; then
    pass "device allocation failure, csg: both distance fields' retries counted ($csg_retries)"
else
    fail "device allocation failure, csg: both distance fields' retries counted" \
        "sdf: '$sdf_retries', csg: '$csg_retries' (expected twice the sdf's)"
fi
rm -f "$WORK/device/"*
"$OCLVOX" voxelize "$MESH" -r 256 --brick-size 128 --reference -q -o "$WORK/device/expected.binvox"

# Every allocation failing is an OpenCL error in the middle of the run (kernels built, triangles
# uploaded): a clear error naming it, no output.
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=0 run voxelize "$MESH" -r 256 --brick-size 128 -q \
    -o "$WORK/device/out.binvox"
if [ "$RC" -eq 1 ] && grep -q "even for a batch of one brick" <<<"$ERR" &&
    grep -q "CL_MEM_OBJECT_ALLOCATION_FAILURE" <<<"$ERR" &&
    [ "$(listing "$WORK/device")" = "expected.binvox " ]; then
    pass "device allocation always failing: retried down to one brick, then exit 1, no output"
else
    fail "device allocation always failing: exit 1 naming the failure, no output" \
        "exit $RC, left: $(listing "$WORK/device"), stderr: ${ERR:0:300}"
fi

# Every allocation failing, in the winding number's point batches: the same error, down to one
# point.
OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=0 run voxelize "$MESH" -r 64 --mode solid --inside winding -q \
    -o "$WORK/device/out.binvox"
if [ "$RC" -eq 1 ] && grep -q "even for a batch of one point" <<<"$ERR" &&
    [ "$(listing "$WORK/device")" = "expected.binvox " ]; then
    pass "winding-number allocation always failing: retried down to one point, exit 1, no output"
else
    fail "winding-number allocation always failing: exit 1 naming the failure, no output" \
        "exit $RC, left: $(listing "$WORK/device"), stderr: ${ERR:0:300}"
fi

# ---------------------------------------------------------------------------------------------
# Host memory: a dense field over the budget (OCLVOX_HOST_MEMORY_MIB) is refused before it is
# allocated, at once, naming its size and the budget; here 149x260x264 voxels at 8 bytes (78 MiB).
# ---------------------------------------------------------------------------------------------
mkdir -p "$WORK/memory"
start=$(date +%s%N)
OCLVOX_HOST_MEMORY_MIB=8 run sdf "$MESH" -r 256 --reference -q -o "$WORK/memory/out.npy"
took_ms=$((($(date +%s%N) - start) / 1000000))
if [ "$RC" -eq 1 ] && grep -q "needs [0-9]* MiB of host memory, over the host memory budget of 8 MiB" <<<"$ERR" &&
    [ -z "$(listing "$WORK/memory")" ] && [ "$took_ms" -lt 2000 ]; then
    pass "dense field over the host budget: exit 1 in $took_ms ms, sizes named, no output"
else
    fail "dense field over the host budget: exit 1 at once, sizes named, no output" \
        "exit $RC after $took_ms ms, left: $(listing "$WORK/memory"), stderr: ${ERR:0:300}"
fi

# ---------------------------------------------------------------------------------------------
# OpenVDB's module (liboclvox_vdb.so, which a shared liboclvox loads from its own folder on the
# first .vdb read) missing: every .vdb is still written (without OpenVDB: occupancy, a narrow
# band's and a full grid's level set), other formats too, and reading a .vdb is refused naming
# the module, leaving nothing. liboclvox is run from a copy in a folder without the module.
# ---------------------------------------------------------------------------------------------
library=$(ldd "$OCLVOX" 2>/dev/null | awk '$1 ~ /^liboclvox\.so/ {print $3}')
if [ -n "$library" ]; then
    mkdir -p "$WORK/lonely" "$WORK/module"
    cp -L "$library" "$WORK/lonely/"
    written=0
    LD_LIBRARY_PATH=$WORK/lonely run sdf "$MESH" -r 32 -q -o "$WORK/module/band.vdb"
    written=$((written + RC))
    LD_LIBRARY_PATH=$WORK/lonely run sdf "$MESH" -r 32 --full -q -o "$WORK/module/full.vdb"
    written=$((written + RC))
    LD_LIBRARY_PATH=$WORK/lonely run voxelize "$MESH" -r 32 -q -o "$WORK/module/out.vdb"
    written=$((written + RC))
    LD_LIBRARY_PATH=$WORK/lonely run voxelize "$MESH" -r 32 -q -o "$WORK/module/out.binvox"
    written=$((written + RC))
    LD_LIBRARY_PATH=$WORK/lonely run mesh "$WORK/module/band.vdb" -q -o "$WORK/module/mesh.obj"
    if [ "$RC" -eq 1 ] && grep -q "the module liboclvox_vdb.so beside liboclvox, could not be loaded" <<<"$ERR" &&
        [ "$written" -eq 0 ] && [ "$(listing "$WORK/module")" = "band.vdb full.vdb out.binvox out.vdb " ]; then
        pass "OpenVDB's module missing: every .vdb and .binvox still written; a .vdb read refused naming it, nothing left"
    else
        fail "OpenVDB's module missing: every output written, a .vdb read refused naming it" \
            "writes' exit codes summed: $written; mesh: exit $RC, stderr: ${ERR:0:300}; left: $(listing "$WORK/module")"
    fi
else
    pass "OpenVDB's module: $OCLVOX links liboclvox statically, OpenVDB with it (nothing to load)"
fi

echo "fault_test: $passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ] || exit 1
[ "$skipped" -eq 0 ] || exit 77
exit 0
