#!/usr/bin/env bash
# Behaviour of the oclvox command-line tool: outputs in every format, the stats JSON against the
# voxels actually written, device against CPU reference, and error cases that must fail with a
# message naming the problem and leave no output behind.
#
# Environment: OCLVOX (the binary), OCLVOX_SAMPLE_DIR (holds spot.obj).
set -u

: "${OCLVOX:?set OCLVOX to the oclvox binary}"
: "${OCLVOX_SAMPLE_DIR:?set OCLVOX_SAMPLE_DIR to the folder holding spot.obj}"
MESH="$OCLVOX_SAMPLE_DIR/spot.obj"

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

source "$(dirname "${BASH_SOURCE[0]}")/shell_checks.sh"

# The checks read outputs with numpy; Debian's python3-numpy (what scripts/install_deps.sh
# installs) lives in the system Python, which another python3 first on PATH may lack.
if ! python3 -c "import numpy" 2>/dev/null && /usr/bin/python3 -c "import numpy" 2>/dev/null; then
    python3() { /usr/bin/python3 "$@"; }
fi

# Runs oclvox with the given arguments; leaves its exit code, stdout and stderr in RC, OUT, ERR.
run() {
    "$OCLVOX" "$@" >"$WORK/stdout" 2>"$WORK/stderr"
    RC=$?
    OUT=$(cat "$WORK/stdout")
    ERR=$(cat "$WORK/stderr")
}

# Count of voxels set in a uint8 .npy file; also fails on any value other than 0 or 1.
npy_ones() {
    python3 - "$1" <<'EOF'
import struct, sys
data = open(sys.argv[1], "rb").read()
assert data[:6] == b"\x93NUMPY", "not an npy file"
header_len = struct.unpack("<H", data[8:10])[0]
body = data[10 + header_len:]
assert set(body) <= {0, 1}, "values other than 0 and 1"
print(sum(body))
EOF
}

# A JSON field (dotted path; lists come out comma-separated), or "invalid" if the file is not
# valid JSON.
json_field() {
    python3 -c '
import json, sys
try:
    value = json.load(open(sys.argv[1]))
except Exception:
    print("invalid"); sys.exit()
for key in sys.argv[2].split("."):
    value = value[key]
print(",".join(map(str, value)) if isinstance(value, list) else value)' "$1" "$2"
}

# expect_failure NAME OUTPUT PATTERN ARGS...: non-zero exit, stderr matches PATTERN
# (case-insensitive extended regex), and neither OUTPUT nor a temporary file beside it exists.
expect_failure() {
    local name=$1 output=$2 pattern=$3
    shift 3
    run "$@"
    local leftovers
    leftovers=$(find "$(dirname "$output")" -maxdepth 1 -name "*$(basename "$output")*" 2>/dev/null)
    if [ "$RC" -eq 0 ]; then
        fail "$name" "exit code 0"
    elif ! grep -qiE "$pattern" <<<"$ERR"; then
        fail "$name" "stderr does not match '$pattern': $ERR"
    elif [ -n "$leftovers" ]; then
        fail "$name" "left output behind: $leftovers"
    else
        pass "$name (exit $RC: $(head -n1 <<<"$ERR"))"
    fi
}

if [ ! -s "$MESH" ]; then
    fail "sample mesh $MESH exists"
    echo "$passed passed, $failed failed"
    exit 1
fi

# ---- basics -------------------------------------------------------------------------------------
run --version
if [ "$RC" -eq 0 ] && grep -qE '^oclvox [0-9]' <<<"$OUT"; then pass "--version ($OUT)"; else
    fail "--version" "rc=$RC out=$OUT"
fi

run devices
if [ "$RC" -eq 0 ] && grep -qE '^[0-9]+:[0-9]+ ' <<<"$OUT" && grep -q 'platform' <<<"$OUT"; then
    pass "devices lists at least one P:D device"
else
    fail "devices" "rc=$RC out=$OUT err=$ERR"
fi
# Whose memory each device works in (what --download auto goes by).
if [ "$(grep -c 'memory ' <<<"$OUT")" = "$(grep -cE "memory .*, (the host's|its own)$" <<<"$OUT")" ]
then
    pass "devices says whose memory each device works in"
else
    fail "devices memory" "$OUT"
fi

run
if [ "$RC" -eq 2 ]; then pass "no command is a usage error (exit 2)"; else fail "no command" "rc=$RC"; fi

# ---- every output format ------------------------------------------------------------------------
for ext in binvox npy vox obj ply; do
    out="$WORK/spot.$ext"
    run voxelize "$MESH" -r 32 -o "$out"
    if [ "$RC" -eq 0 ] && [ -s "$out" ]; then pass "voxelize to .$ext"; else
        fail "voxelize to .$ext" "rc=$RC err=$ERR"
    fi
done
head -c 7 "$WORK/spot.binvox" | grep -q '#binvox' && pass ".binvox header" || fail ".binvox header"
head -c 4 "$WORK/spot.vox" | grep -q 'VOX ' && pass ".vox header" || fail ".vox header"
grep -q '^v ' "$WORK/spot.obj" && grep -q '^f ' "$WORK/spot.obj" && pass ".obj has cube faces" ||
    fail ".obj has cube faces"
if [ "$(json_field "$WORK/spot.npy.json" voxel_size)" != invalid ]; then
    pass ".npy.json sidecar"
else
    fail ".npy.json sidecar"
fi

# The last run above was not --quiet and its stderr is a file: a summary, no progress bar.
if grep -qE '\([0-9]+ triangles\)' <<<"$OUT" && grep -qE 'voxels +[1-9][0-9]* set' <<<"$OUT" &&
    grep -q 'spot.ply' <<<"$OUT" && [ -z "$ERR" ]; then
    pass "summary on stdout, nothing on a non-terminal stderr"
else
    fail "summary" "out=$OUT err=$ERR"
fi

# ---- stats JSON against the voxels written ------------------------------------------------------
run voxelize "$MESH" -r 32 -o "$WORK/device.npy" --stats-json "$WORK/device.json" --quiet
device_ones=$(npy_ones "$WORK/device.npy")
device_set=$(json_field "$WORK/device.json" voxels_set)
if [ "$RC" -eq 0 ] && [ -z "$OUT" ]; then pass "--quiet prints nothing"; else
    fail "--quiet" "rc=$RC out=$OUT"
fi
if [ "$device_set" != invalid ] && [ "$device_set" -gt 0 ] 2>/dev/null &&
    [ "$device_set" = "$device_ones" ]; then
    pass "--stats-json voxels_set ($device_set) equals the ones in the .npy"
else
    fail "--stats-json voxels_set" "json=$device_set npy=$device_ones"
fi
dims=$(json_field "$WORK/device.json" grid.dims)
longest=$(tr , '\n' <<<"$dims" | sort -n | tail -n1)
if [ "$longest" = 32 ] && [ "$(json_field "$WORK/device.json" backend)" = opencl ]; then
    pass "--stats-json grid $dims, longest axis 32, backend opencl"
else
    fail "--stats-json grid" "dims=$dims"
fi

run voxelize "$MESH" -r 32 -o "$WORK/reference.npy" --reference --stats-json "$WORK/reference.json"
reference_ones=$(npy_ones "$WORK/reference.npy")
if [ "$RC" -eq 0 ] && [ "$reference_ones" = "$device_ones" ] &&
    cmp -s "$WORK/reference.npy" "$WORK/device.npy"; then
    pass "--reference sets the same $reference_ones voxels as the device"
else
    fail "--reference" "rc=$RC reference=$reference_ones device=$device_ones err=$ERR"
fi
grep -q 'CPU reference' <<<"$OUT" && pass "summary names the CPU reference" ||
    fail "summary names the CPU reference" "$OUT"

# Both downloads give the same file; the compact one reports fewer bytes brought back.
run voxelize "$MESH" -r 48 --mode filled --brick-size 16 --device-memory 1 --download whole \
    -o "$WORK/whole.binvox" --stats-json "$WORK/whole.json" -q
run voxelize "$MESH" -r 48 --mode filled --brick-size 16 --device-memory 1 --download blocks \
    -o "$WORK/blocks.binvox" --stats-json "$WORK/blocks.json" -q
whole_bytes=$(json_field "$WORK/whole.json" bytes_downloaded)
blocks_bytes=$(json_field "$WORK/blocks.json" bytes_downloaded)
if [ "$RC" -eq 0 ] && cmp -s "$WORK/whole.binvox" "$WORK/blocks.binvox" &&
    [ "$blocks_bytes" -gt 0 ] 2>/dev/null && [ "$blocks_bytes" -lt "$whole_bytes" ]; then
    pass "--download blocks writes the --download whole file ($blocks_bytes of $whole_bytes bytes)"
else
    fail "--download blocks" "rc=$RC bytes=$blocks_bytes whole=$whole_bytes err=$ERR"
fi

run voxelize "$MESH" -r 32 --test pef -o "$WORK/sat.npy" --stats
sat_ones=$(npy_ones "$WORK/sat.npy")
if [ "$RC" -eq 0 ] && [ "$sat_ones" -gt 0 ] 2>/dev/null && grep -q 'kernels' <<<"$OUT" &&
    grep -q 'triangles/s' <<<"$OUT"; then
    pass "--test pef --stats ($sat_ones voxels; the default sat set $device_ones)"
else
    fail "--test pef --stats" "rc=$RC ones=$sat_ones out=$OUT err=$ERR"
fi

run voxelize "$MESH" -r 16 --cubic -o "$WORK/cubic.npy" --stats-json "$WORK/cubic.json" -q
dims=$(json_field "$WORK/cubic.json" grid.dims)
[ "$dims" = 16,16,16 ] && pass "--cubic -r 16 gives 16x16x16" || fail "--cubic" "dims=$dims"

run voxelize "$MESH" --voxel-size 0.1 --origin -1,-1,-1 --dims 20,20,20 --pad 2 -q \
    -o "$WORK/explicit.npy" --stats-json "$WORK/explicit.json"
dims=$(json_field "$WORK/explicit.json" grid.dims)
origin=$(json_field "$WORK/explicit.json" grid.origin | cut -d, -f1)
if [ "$dims" = 24,24,24 ] && python3 -c "import sys; sys.exit(abs($origin + 1.2) > 1e-9)"; then
    pass "--voxel-size --origin --dims --pad give a 24^3 grid at -1.2"
else
    fail "explicit grid" "rc=$RC dims=$dims origin=$origin err=$ERR"
fi

# A terminal gets a progress bar (script(1) gives the command a pseudo-terminal), for every long
# phase: voxelizing, writing, distance fields, meshing; --quiet silences it.
if command -v script >/dev/null; then
    tty_bars() {  # command line -> the labels of the bars it drew, comma-separated
        script -qec "$1" /dev/null </dev/null 2>&1 | tr '\r' '\n' |
            sed -n 's/^\([a-z ]*\) \[[#.]*\].*/\1/p' | sort -u | tr '\n' ,
    }
    bars=$(tty_bars "'$OCLVOX' voxelize '$MESH' -r 32 -o '$WORK/tty.binvox'")
    [ "$bars" = "loading,voxelizing,writing," ] && pass "progress bars on a terminal (loading, voxelizing, writing)" ||
        fail "progress bar on a terminal" "bars: $bars"
    bars=$(tty_bars "'$OCLVOX' sdf '$MESH' -r 64 -o '$WORK/tty.npy' --mesh '$WORK/tty.obj'")
    [ "$bars" = "distance field,loading,meshing,writing," ] && pass "sdf --mesh: loading, distance field, meshing and writing bars" ||
        fail "sdf --mesh progress bars" "bars: $bars"
    bars=$(tty_bars "'$OCLVOX' csg '$MESH' union '$MESH' -r 48 -o '$WORK/tty_csg.obj'")
    [ "$bars" = "distance fields,loading,meshing,writing," ] && pass "csg: loading, distance fields, meshing and writing bars" ||
        fail "csg progress bars" "bars: $bars"
    bars=$(tty_bars "'$OCLVOX' sdf '$MESH' -r 64 -o '$WORK/tty.npy' --quiet")
    [ -z "$bars" ] && pass "--quiet draws no progress bar" || fail "--quiet progress bar" "$bars"
fi

# ---- errors -------------------------------------------------------------------------------------
printf 'hello\nthis is not an obj file \x01\x02\xff\n' >"$WORK/garbage.obj"
: >"$WORK/empty.obj"
printf 'v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n' >"$WORK/nan.obj"
cp "$MESH" "$WORK/mesh.xyz"
o="$WORK/err.binvox"

expect_failure "missing input" "$o" 'no-such-mesh' voxelize "$WORK/no-such-mesh.obj" -o "$o"
expect_failure "empty input file" "$o" 'empty|triangle' voxelize "$WORK/empty.obj" -o "$o"
expect_failure "garbage .obj" "$o" 'garbage|triangle|parse' voxelize "$WORK/garbage.obj" -o "$o"
expect_failure "NaN coordinate" "$o" 'nan|finite' voxelize "$WORK/nan.obj" -o "$o"
expect_failure "unknown input extension" "$o" 'xyz' voxelize "$WORK/mesh.xyz" -o "$o"
expect_failure "unknown output extension" "$WORK/out.xyz" 'xyz' voxelize "$MESH" -o "$WORK/out.xyz"
expect_failure "output into a missing folder" "$WORK/missing/out.binvox" 'missing.*not exist' \
    voxelize "$MESH" -o "$WORK/missing/out.binvox"
expect_failure "--stats-json into a missing folder" "$o" 'missing.*not exist' \
    voxelize "$MESH" -o "$o" --stats-json "$WORK/missing/stats.json"
expect_failure "-r 0" "$o" 'resolution' voxelize "$MESH" -r 0 -o "$o"
expect_failure "-r 100000000" "$o" 'resolution' voxelize "$MESH" -r 100000000 -o "$o"
expect_failure "--resolution=-5" "$o" 'resolution' voxelize "$MESH" --resolution=-5 -o "$o"
expect_failure "--voxel-size nan" "$o" 'voxel-size' voxelize "$MESH" --voxel-size nan -o "$o"
expect_failure "--origin 1,2" "$o" 'origin' voxelize "$MESH" --origin 1,2 -o "$o"
expect_failure "--origin 1,2,nan" "$o" 'origin' voxelize "$MESH" --origin 1,2,nan -o "$o"
expect_failure "--dims 8,0,8" "$o" 'dims' voxelize "$MESH" --dims 8,0,8 -o "$o"
expect_failure "--brick-size 6" "$o" 'brick-size' voxelize "$MESH" --brick-size 6 -o "$o"
expect_failure "--test foo" "$o" 'foo|--test' voxelize "$MESH" --test foo -o "$o"
expect_failure "--device no-such-device" "$o" 'no-such-device' \
    voxelize "$MESH" -r 32 --device no-such-device -o "$o"
OCLVOX_DEVICE=no-such-device expect_failure "OCLVOX_DEVICE=no-such-device" "$o" 'no-such-device' \
    voxelize "$MESH" -r 32 -o "$o"

# With no OpenCL platform (an empty ICD folder for the loader, and no drivers named in
# OCL_ICD_FILENAMES, which a GPU machine may set) devices fail clearly and the CPU reference still
# works. A loader that does not read OCL_ICD_VENDORS (some drivers ship their own) cannot be shown
# an empty folder, so there the first check is skipped, saying why.
mkdir "$WORK/no-icds"
loader=$(ldd "$OCLVOX" | awk '/libOpenCL/ { print $3 }')
if [ -n "$loader" ] && grep -q OCL_ICD_VENDORS "$(readlink -f "$loader")"; then
    OCL_ICD_FILENAMES= OCL_ICD_VENDORS="$WORK/no-icds" expect_failure \
        "devices without an OpenCL platform" "$o" 'platform' devices
else
    skip "devices without an OpenCL platform: the OpenCL loader ($loader) does not read OCL_ICD_VENDORS"
fi
OCL_ICD_FILENAMES= OCL_ICD_VENDORS="$WORK/no-icds" run voxelize "$MESH" -r 32 --reference -q -o "$WORK/no-icd.npy"
[ "$RC" -eq 0 ] && [ "$(npy_ones "$WORK/no-icd.npy")" = "$reference_ones" ] &&
    pass "--reference works without an OpenCL platform" ||
    fail "--reference without an OpenCL platform" "rc=$RC err=$ERR"

run voxelize "$MESH" -r 0 -o "$o"
[ "$RC" -eq 2 ] && pass "bad option values are usage errors (exit 2)" || fail "-r 0 exit code" "rc=$RC"
run voxelize "$WORK/no-such-mesh.obj" -o "$o"
grep -q '^oclvox: error: ' <<<"$ERR" && [ "$RC" -eq 1 ] && pass "run errors: 'oclvox: error:', exit 1" ||
    fail "run error format" "rc=$RC err=$ERR"

# ---- distance fields: sdf, csg, mesh ------------------------------------------------------------
# "min max count" of a float32/float64 .npy file (little-endian), or "invalid".
npy_float_range() {
    python3 - "$1" <<'EOF_PY'
import ast, struct, sys
try:
    data = open(sys.argv[1], "rb").read()
    assert data[:6] == b"\x93NUMPY"
    if data[6] == 1:
        header_len, start = struct.unpack("<H", data[8:10])[0], 10
    else:
        header_len, start = struct.unpack("<I", data[8:12])[0], 12
    header = ast.literal_eval(data[start:start + header_len].decode("latin1"))
    code = {"<f4": "f", "<f8": "d"}[header["descr"]]
    body = data[start + header_len:]
    values = struct.unpack("<%d%s" % (len(body) // struct.calcsize(code), code), body)
    print(min(values), max(values), len(values))
except Exception:
    print("invalid")
EOF_PY
}

# Number of faces ("f" lines) of an OBJ file.
obj_faces() {
    grep -c '^f ' "$1" 2>/dev/null || echo 0
}

run sdf "$MESH" -r 24 -o "$WORK/sdf.npy"
read -r sdf_min sdf_max sdf_count <<<"$(npy_float_range "$WORK/sdf.npy")"
if [ "$RC" -eq 0 ] && [ -s "$WORK/sdf.npy.json" ] &&
    python3 -c "import sys; sys.exit(not ($sdf_min < 0 < $sdf_max))" 2>/dev/null; then
    pass "sdf to .npy with sidecar: $sdf_count samples in [$sdf_min, $sdf_max]"
else
    fail "sdf to .npy" "rc=$RC range=$sdf_min $sdf_max err=$ERR"
fi
grep -qE '\([0-9]+ triangles\)' <<<"$OUT" && grep -q '^grid ' <<<"$OUT" &&
    grep -q '^device ' <<<"$OUT" && pass "sdf summary (input, grid, device)" ||
    fail "sdf summary" "$OUT"

run sdf "$MESH" -r 24 -o "$WORK/sdf.vdb" --quiet
[ "$RC" -eq 0 ] && [ -s "$WORK/sdf.vdb" ] && [ -z "$OUT" ] && pass "sdf to .vdb" ||
    fail "sdf to .vdb" "rc=$RC err=$ERR"

# A narrow band is computed sparse, a full grid dense: two separate paths that must agree exactly
# within the band, and the sparse .vdb (read by OpenVDB's own Python module) must hold exactly the
# band's samples of the .npy.
"$OCLVOX" sdf "$MESH" -r 24 --full -q -o "$WORK/sdf_full.npy"
vdb_python=python3  # Debian's python3-openvdb lives in the system Python
/usr/bin/python3 -c "import numpy, pyopenvdb" 2>/dev/null && vdb_python=/usr/bin/python3
verdict=$("$vdb_python" - "$WORK/sdf.npy" "$WORK/sdf_full.npy" "$WORK/sdf.vdb" <<'EOF_PY' 2>&1
import json, sys
import numpy as np
narrow, full = np.load(sys.argv[1]), np.load(sys.argv[2])
background = json.load(open(sys.argv[1] + ".json"))["background"]
band = np.abs(narrow) < np.float32(background)
assert band.any() and np.array_equal(narrow[band], full[band]), "band samples differ"
assert np.all(np.abs(narrow[~band]) == np.float32(background)), "off-band samples"
try:
    import pyopenvdb as vdb
except ImportError:
    print("ok (no pyopenvdb)")
    sys.exit(0)
grid = vdb.read(sys.argv[3], "sdf")
dense = np.zeros(narrow.shape, np.float32)
grid.copyToArray(dense, ijk=(0, 0, 0))
assert grid.activeVoxelCount() == band.sum(), (grid.activeVoxelCount(), band.sum())
assert np.array_equal(dense[band], narrow[band]), "vdb band values"
print("ok")
EOF_PY
)
[[ "$verdict" == ok* ]] &&
    pass "sdf: sparse narrow band equals the dense full grid in the band; .vdb holds exactly it ($verdict)" ||
    fail "sdf: sparse narrow band vs dense full grid" "$verdict"

run sdf "$MESH" -r 32 --reference -o "$WORK/sdf_mesh.npy" --mesh "$WORK/sdf_mesh.obj"
faces=$(obj_faces "$WORK/sdf_mesh.obj")
if [ "$RC" -eq 0 ] && [ "$faces" -gt 100 ] && grep -qE 'mesh +[0-9]+ triangles' <<<"$OUT"; then
    pass "sdf --mesh gives an OBJ with $faces faces"
else
    fail "sdf --mesh" "rc=$RC faces=$faces err=$ERR"
fi

# A copy of the sample moved along x by 40% of its width, so the two overlap in part.
python3 - "$MESH" "$WORK/spot_moved.obj" <<'EOF_PY'
import sys
lines = open(sys.argv[1]).read().splitlines()
xs = [float(l.split()[1]) for l in lines if l.startswith("v ")]
shift = 0.4 * (max(xs) - min(xs))
with open(sys.argv[2], "w") as out:
    for l in lines:
        if l.startswith("v "):
            p = l.split()
            p[1] = repr(float(p[1]) + shift)
            l = " ".join(p)
        out.write(l + "\n")
EOF_PY
declare -A csg_faces
for op in union intersection difference; do
    run csg "$MESH" "$op" "$WORK/spot_moved.obj" -r 28 -q -o "$WORK/csg_$op.obj"
    csg_faces[$op]=$(obj_faces "$WORK/csg_$op.obj")
    if [ "$RC" -eq 0 ] && [ "${csg_faces[$op]}" -gt 0 ]; then
        pass "csg $op gives an OBJ with ${csg_faces[$op]} faces"
    else
        fail "csg $op" "rc=$RC faces=${csg_faces[$op]} err=$ERR"
    fi
done
# A narrow-band csg of meshes is sparse, a full-grid one dense: equal within the band, and the
# sparse difference's .vdb (its leaves combined) holds exactly the band of its .npy.
"$OCLVOX" csg "$MESH" difference "$WORK/spot_moved.obj" -r 28 -q -o "$WORK/csg_narrow.npy"
"$OCLVOX" csg "$MESH" difference "$WORK/spot_moved.obj" -r 28 -q -o "$WORK/csg_narrow.vdb"
"$OCLVOX" csg "$MESH" difference "$WORK/spot_moved.obj" -r 28 --full -q -o "$WORK/csg_full.npy"
verdict=$("$vdb_python" - "$WORK/csg_narrow.npy" "$WORK/csg_full.npy" "$WORK/csg_narrow.vdb" \
    <<'EOF_PY' 2>&1
import json, sys
import numpy as np
narrow, full = np.load(sys.argv[1]), np.load(sys.argv[2])
background = np.float32(json.load(open(sys.argv[1] + ".json"))["background"])
band = np.abs(narrow) < background
assert band.any() and (narrow < 0).any(), "empty band or no inside"
# Full-grid distances are below the band's clamp wherever the narrow band is, so each band
# sample is the full-grid sample; off the band both fields agree in sign.
assert np.array_equal(narrow[band], full[band]), "band samples differ"
assert np.array_equal(narrow[~band] < 0, full[~band] < 0), "signs off the band differ"
try:
    import pyopenvdb as vdb
except ImportError:
    print("ok (no pyopenvdb)")
    sys.exit(0)
grid = vdb.read(sys.argv[3], "sdf")
assert grid.activeVoxelCount() == band.sum(), (grid.activeVoxelCount(), band.sum())
print("ok")
EOF_PY
)
[[ "$verdict" == ok* ]] &&
    pass "csg: sparse narrow band equals the dense full grid in the band; .vdb holds it ($verdict)" ||
    fail "csg: sparse narrow band vs dense full grid" "$verdict"

# A full grid is computed a slab of layers at a time (8 layers under a 1 MiB host budget, 24 under
# 4 MiB, the whole grid in one slab under the default budget), without the whole field in memory: written to .npy
# or .vdb as it comes, and gathered into its meshing view for --mesh and --preview. The same .npy
# bit for bit, the same sidecar but for its name, the same report of the border and of the inside
# voxels, and (read by OpenVDB) the same .vdb voxels and background. The same for csg. The mesh of
# the full grid of a closed mesh is the narrow band's (its sign changes lie within the band),
# which the sparse band path computes on its own: the same file byte for byte.
OCLVOX_HOST_MEMORY_MIB=4 "$OCLVOX" sdf "$MESH" -r 64 --full -q -o "$WORK/slabs.npy" \
    --mesh "$WORK/slabs.obj" --preview "$WORK/slabs.png" --stats-json "$WORK/slabs.json"
"$OCLVOX" sdf "$MESH" -r 64 --full -q -o "$WORK/whole.npy" --stats-json "$WORK/whole.json"
"$OCLVOX" sdf "$MESH" -r 64 -q -o "$WORK/band64.vdb" --mesh "$WORK/band64.obj" \
    --preview "$WORK/band64.png"
OCLVOX_HOST_MEMORY_MIB=1 "$OCLVOX" sdf "$MESH" -r 64 --full -q -o "$WORK/slabs.vdb"
"$OCLVOX" sdf "$MESH" -r 64 --full -q -o "$WORK/whole.vdb"
OCLVOX_HOST_MEMORY_MIB=1 "$OCLVOX" csg "$MESH" union "$WORK/spot_moved.obj" -r 48 --full -q \
    -o "$WORK/csg_slabs.npy" --stats-json "$WORK/csg_slabs.json"
"$OCLVOX" csg "$MESH" union "$WORK/spot_moved.obj" -r 48 --full -q \
    -o "$WORK/csg_whole.npy" --stats-json "$WORK/csg_whole.json"
OCLVOX_HOST_MEMORY_MIB=4 "$OCLVOX" csg "$MESH" union "$WORK/spot_moved.obj" -r 48 --full -q \
    -o "$WORK/csg_slabs.obj"
"$OCLVOX" csg "$MESH" union "$WORK/spot_moved.obj" -r 48 -q -o "$WORK/csg_band.obj"
for pair in slabs.obj:band64.obj slabs.png:band64.png csg_slabs.obj:csg_band.obj; do
    a="$WORK/${pair%%:*}" b="$WORK/${pair##*:}"
    [ -s "$a" ] && cmp -s "$a" "$b" &&
        pass "--full in slabs with a mesh or preview: ${pair%%:*} is ${pair##*:} byte for byte" ||
        fail "--full in slabs: ${pair%%:*} vs ${pair##*:}" "they differ"
done
verdict=$("$vdb_python" - "$WORK" <<'EOF_PY' 2>&1
import json, sys
work = sys.argv[1]
try:
    import numpy as np, pyopenvdb as vdb
    a, b = (vdb.read(f"{work}/{n}.vdb", "sdf") for n in ("slabs", "whole"))
    assert a.activeVoxelCount() == b.activeVoxelCount() > 30 * 30 * 30, "active voxels"
    assert a.background == b.background > 0, "background"
    dense = [np.zeros((80, 80, 80), np.float32) for _ in "ab"]
    a.copyToArray(dense[0], ijk=(-2, -2, -2))
    b.copyToArray(dense[1], ijk=(-2, -2, -2))
    assert np.array_equal(dense[0].view(np.uint32), dense[1].view(np.uint32)), "vdb values"
except ImportError:
    pass
for slabs, whole in (("slabs", "whole"), ("csg_slabs", "csg_whole")):
    a, b = (open(f"{work}/{n}.npy", "rb").read() for n in (slabs, whole))
    assert len(a) > 20 * 20 * 20 * 4 and a == b, f"{slabs}.npy differs"
    sa, sb = (json.load(open(f"{work}/{n}.npy.json")) for n in (slabs, whole))
    sa.pop("file"), sb.pop("file")
    assert sa == sb, (sa, sb)
    ra, rb = (json.load(open(f"{work}/{n}.json")) for n in (slabs, whole))
    for key in ("border_samples_inside", "voxels_set", "triangles"):
        assert ra[key] == rb[key], (key, ra[key], rb[key])
    assert ra["voxels_set"] > 0
print("ok")
EOF_PY
)
[ "$verdict" = ok ] && pass "sdf/csg --full to .npy/.vdb in slabs: the whole field's files and report" ||
    fail "sdf/csg --full in slabs" "$verdict"

# .vdb level sets are read sparse: the sdf's .vdb meshes to the very file `sdf --mesh` wrote, and
# two .vdb fields on the csg's grid combine to the very samples the csg of the meshes gave.
run sdf "$MESH" -r 32 -q -o "$WORK/level_set.vdb" --mesh "$WORK/level_set_direct.obj"
run mesh "$WORK/level_set.vdb" -o "$WORK/level_set_read.obj"
if [ "$RC" -eq 0 ] && cmp -s "$WORK/level_set_direct.obj" "$WORK/level_set_read.obj" &&
    grep -qE 'level set' <<<"$OUT"; then
    pass "mesh of a .vdb level set equals sdf --mesh byte for byte"
else
    fail "mesh of a .vdb level set" "rc=$RC out=$OUT err=$ERR"
fi
grid_of() {  # --origin X,Y,Z --voxel-size H --dims NX,NY,NZ of a .npy sidecar
    python3 -c "
import json, sys
s = json.load(open(sys.argv[1]))
print('--origin', ','.join(repr(v) for v in s['origin']), '--voxel-size', repr(s['voxel_size']),
      '--dims', ','.join(str(v) for v in s['dims']))" "$1"
}
read -r -a csg_grid <<<"$(grid_of "$WORK/csg_narrow.npy.json")"
"$OCLVOX" sdf "$MESH" "${csg_grid[@]}" -q -o "$WORK/csg_a.vdb"
"$OCLVOX" sdf "$WORK/spot_moved.obj" "${csg_grid[@]}" -q -o "$WORK/csg_b.vdb"
run csg "$WORK/csg_a.vdb" difference "$WORK/csg_b.vdb" -q -o "$WORK/csg_of_vdbs.npy"
if [ "$RC" -eq 0 ] && python3 -c "
import sys
a, b = (open(p, 'rb').read() for p in sys.argv[1:3])
sys.exit(a != b)" "$WORK/csg_narrow.npy" "$WORK/csg_of_vdbs.npy"; then
    pass "csg of two .vdb level sets equals the csg of their meshes sample for sample"
else
    fail "csg of two .vdb level sets" "rc=$RC err=$ERR"
fi
# .npy fields are read a layer at a time (Fortran order, as oclvox writes them) or whole (C order):
# two on the csg's grid combine to numpy's max(a, -b) of them, which is the csg of the meshes'
# field; meshed, to the csg of the meshes' own mesh; and a C-order copy meshes as the original.
"$OCLVOX" sdf "$MESH" "${csg_grid[@]}" -q -o "$WORK/csg_a.npy"
"$OCLVOX" sdf "$WORK/spot_moved.obj" "${csg_grid[@]}" -q -o "$WORK/csg_b.npy"
"$OCLVOX" csg "$MESH" difference "$WORK/spot_moved.obj" "${csg_grid[@]}" -q \
    -o "$WORK/csg_meshes.obj"
"$OCLVOX" csg "$WORK/csg_a.npy" difference "$WORK/csg_b.npy" -q -o "$WORK/csg_of_npys.obj"
"$OCLVOX" mesh "$WORK/csg_a.npy" -q -o "$WORK/a_fortran.obj"
run csg "$WORK/csg_a.npy" difference "$WORK/csg_b.npy" -q -o "$WORK/csg_of_npys.npy"
verdict=$("$vdb_python" - "$WORK" <<'EOF_PY' 2>&1
import json, shutil, sys
import numpy as np
work = sys.argv[1]
a, b, got, meshes = (np.load(f"{work}/{n}.npy") for n in ("csg_a", "csg_b", "csg_of_npys",
                                                            "csg_narrow"))
assert np.isfortran(a) and a.shape == got.shape, "layout"
assert np.array_equal(got, np.maximum(a, -b)), "not max(a, -b)"
assert np.array_equal(got, meshes), "not the csg of the meshes"
np.save(f"{work}/a_c_order.npy", np.ascontiguousarray(a))
shutil.copy(f"{work}/csg_a.npy.json", f"{work}/a_c_order.npy.json")
print("ok")
EOF_PY
)
"$OCLVOX" mesh "$WORK/a_c_order.npy" -q -o "$WORK/a_c_order.obj"
if [ "$RC" -eq 0 ] && [ "$verdict" = ok ] && cmp -s "$WORK/csg_of_npys.obj" "$WORK/csg_meshes.obj" &&
    cmp -s "$WORK/a_fortran.obj" "$WORK/a_c_order.obj" && [ -s "$WORK/a_c_order.obj" ]; then
    pass "csg of two .npy fields: max(a, -b) layer by layer, the meshes' csg field and mesh; C order too"
else
    fail "csg and mesh of .npy fields a layer at a time" "rc=$RC $verdict err=$ERR"
fi
# Level sets on one lattice but different grids (b's origin whole voxels away, its dims
# smaller) combine on the box of both; half a voxel away they are refused.
moved_grid() {  # the csg grid's options with the origin moved by (dx, dy, dz) voxels
    python3 -c "
import json, sys
s = json.load(open(sys.argv[1]))
h, move = s['voxel_size'], [float(v) for v in sys.argv[2:5]]
print('--origin', ','.join(repr(o + m * h) for o, m in zip(s['origin'], move)), '--voxel-size',
      repr(h), '--dims', ','.join(str(d - 4) for d in s['dims']))" "$@"
}
read -r -a lattice_grid <<<"$(moved_grid "$WORK/csg_narrow.npy.json" 3 -2 5)"
"$OCLVOX" sdf "$WORK/spot_moved.obj" "${lattice_grid[@]}" -q -o "$WORK/lattice_b.vdb"
run csg "$WORK/csg_a.vdb" union "$WORK/lattice_b.vdb" -o "$WORK/lattice.vdb" --json
if [ "$RC" -eq 0 ] && python3 -c "
import json, sys
grid, before = json.loads(sys.argv[1])['grid'], json.load(open(sys.argv[2]))
want = [max(d, m + d - 4) - min(0, m) for d, m in zip(before['dims'], (3, -2, 5))]
sys.exit(grid['dims'] != want)" "$OUT" "$WORK/csg_narrow.npy.json"; then
    pass "csg of .vdb level sets on one lattice covers the box of both grids"
else
    fail "csg of .vdb level sets on one lattice" "rc=$RC out=$OUT err=$ERR"
fi
expect_failure "csg of a .npy and a .vdb field" "$WORK/mixed.npy" 'two \.npy fields or two \.vdb' \
    csg "$WORK/csg_narrow.npy" union "$WORK/csg_a.vdb" -o "$WORK/mixed.npy"
expect_failure "mesh of a .vdb on a named device" "$WORK/vdb_on_device.obj" 'host.*--device' \
    mesh "$WORK/level_set.vdb" --device 0 -o "$WORK/vdb_on_device.obj"
# $OCLVOX_DEVICE is only the default device of the commands that use one: set in the environment
# (even to a device that does not exist) it must not stop a field from being meshed or combined.
OCLVOX_DEVICE=no-such-device run mesh "$WORK/level_set.vdb" -q -o "$WORK/vdb_env_device.obj"
[ "$RC" -eq 0 ] && [ -s "$WORK/vdb_env_device.obj" ] &&
    OCLVOX_DEVICE=no-such-device run csg "$WORK/csg_a.vdb" union "$WORK/lattice_b.vdb" -q \
        -o "$WORK/env_device.vdb" && [ "$RC" -eq 0 ] && [ -s "$WORK/env_device.vdb" ] &&
    pass "mesh and csg of field files ignore \$OCLVOX_DEVICE (only --device is refused)" ||
    fail "mesh and csg of field files with \$OCLVOX_DEVICE set" "rc=$RC err=$ERR"
printf 'not a vdb' >"$WORK/not_vdb.vdb"
expect_failure "mesh of a file that is not a .vdb" "$WORK/from_not_vdb.obj" 'not_vdb\.vdb.*not a readable' \
    mesh "$WORK/not_vdb.vdb" -o "$WORK/from_not_vdb.obj"
[ "${csg_faces[union]}" != "${csg_faces[intersection]}" ] &&
    pass "csg union and intersection differ (${csg_faces[union]} vs ${csg_faces[intersection]} faces)" ||
    fail "csg union equals intersection" "${csg_faces[union]} faces"

# ---- field meshes are closed by default ---------------------------------------------------------
# sdf and csg pad fitted grids by band + 1 voxels and mesh with Marching Cubes, so their meshes are
# closed and manifold. "border B non-manifold N oriented O vertex-manifold M euler X" of an OBJ:
# edges used by an odd number of triangles, edges not used by exactly two, every directed edge
# once with its reverse once, the triangles around every vertex forming one fan, V - E + F.
obj_topology() {
    python3 - "$1" <<'EOF_PY'
import sys
from collections import defaultdict
triangles = [tuple(int(w.split("/")[0]) - 1 for w in l.split()[1:4])
             for l in open(sys.argv[1]) if l.startswith("f ")]
undirected, directed, fan = defaultdict(int), defaultdict(int), defaultdict(dict)
vertex_manifold = True
for t in triangles:
    for i in range(3):
        a, b, c = t[i], t[(i + 1) % 3], t[(i + 2) % 3]
        undirected[min(a, b), max(a, b)] += 1
        directed[a, b] += 1
        vertex_manifold &= b not in fan[a]
        fan[a][b] = c
for links in fan.values():  # following b -> c around a vertex must visit every triangle once
    start = at = next(iter(links))
    for steps in range(1, len(links) + 1):
        at = links.get(at)
        if at is None or at == start:
            break
    vertex_manifold &= at == start and steps == len(links)
oriented = all(n == 1 and directed.get((b, a)) == 1 for (a, b), n in directed.items())
print("border %d non-manifold %d oriented %d vertex-manifold %d euler %d" % (
    sum(n % 2 for n in undirected.values()), sum(n != 2 for n in undirected.values()),
    oriented, vertex_manifold, len(fan) - len(undirected) + len(triangles)))
EOF_PY
}

# An icosphere OBJ (4 subdivisions of an icosahedron): centre X,Y,Z and radius.
sphere_obj() {
    python3 - "$@" <<'EOF_PY'
import math, sys
path, cx, cy, cz, r = sys.argv[1], *map(float, sys.argv[2:6])
g = (1 + 5 ** 0.5) / 2
v = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g),
     (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
     (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
     (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
for _ in range(4):
    mid, nf = {}, []
    def m(a, b):
        if (b, a) in mid: return mid[b, a]
        v.append(tuple((p + q) / 2 for p, q in zip(v[a], v[b]))); mid[a, b] = len(v) - 1
        return mid[a, b]
    for a, b, c in f:
        ab, bc, ca = m(a, b), m(b, c), m(c, a)
        nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    f = nf
with open(path, "w") as out:
    for p in v:
        n = math.sqrt(sum(x * x for x in p))
        out.write("v %r %r %r\n" % (cx + r * p[0] / n, cy + r * p[1] / n, cz + r * p[2] / n))
    for a, b, c in f:
        out.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
EOF_PY
}

closed_genus0="border 0 non-manifold 0 oriented 1 vertex-manifold 1 euler 2"
run sdf "$MESH" -r 40 -o "$WORK/closed.npy" --mesh "$WORK/closed.obj"
topology=$(obj_topology "$WORK/closed.obj")
[ "$RC" -eq 0 ] && [ "$topology" = "$closed_genus0" ] && ! grep -q '^warning' <<<"$OUT" &&
    pass "sdf --mesh with the defaults is closed, manifold, genus 0 like the input" ||
    fail "sdf --mesh with the defaults" "rc=$RC $topology out=$OUT err=$ERR"

sphere_obj "$WORK/ball_a.obj" 0 0 0 1
sphere_obj "$WORK/ball_b.obj" 0.83 0.31 -0.27 0.8
# A level set on another lattice (half a voxel off A's, and 1.3 times A's voxel) is rebuilt on A's
# (OpenVDB's levelSetRebuild): the union lies on A's lattice, and near the surface it is the union
# of both computed on A's grid to within a fraction of a voxel (half a voxel off would be 0.5).
"$OCLVOX" csg "$WORK/ball_a.obj" union "$WORK/ball_b.obj" -r 40 -q -o "$WORK/balls.vdb" \
    --json >"$WORK/ball_a.json"  # a grid that holds both balls
read -r -a ball_grid <<<"$(python3 -c "
import json, sys
g = json.load(open(sys.argv[1]))['grid']
print('--origin', ','.join(repr(o) for o in g['origin']), '--voxel-size', repr(g['voxel_size']),
      '--dims', ','.join(str(d) for d in g['dims']))" "$WORK/ball_a.json")"
read -r -a ball_off_grid <<<"$(python3 -c "
import json, sys
g = json.load(open(sys.argv[1]))['grid']
h = g['voxel_size']
print('--origin', ','.join(repr(o + 0.5 * h) for o in g['origin']), '--voxel-size', repr(1.3 * h),
      '--dims', ','.join(str(int(d / 1.3) + 1) for d in g['dims']))" "$WORK/ball_a.json")"
"$OCLVOX" sdf "$WORK/ball_a.obj" "${ball_grid[@]}" -q -o "$WORK/ball_a.vdb"
"$OCLVOX" sdf "$WORK/ball_b.obj" "${ball_grid[@]}" -q -o "$WORK/ball_b.vdb"
"$OCLVOX" sdf "$WORK/ball_b.obj" "${ball_off_grid[@]}" -q -o "$WORK/ball_b_off.vdb"
"$OCLVOX" csg "$WORK/ball_a.vdb" union "$WORK/ball_b.vdb" -q -o "$WORK/on_lattice.npy"
run csg "$WORK/ball_a.vdb" union "$WORK/ball_b_off.vdb" -q -o "$WORK/off_lattice.npy"
verdict=$("$vdb_python" - "$WORK" <<'EOF_PY' 2>&1
import json, sys
import numpy as np
work = sys.argv[1]
(on, on_side), (off, off_side) = ((np.load(f"{work}/{n}.npy"), json.load(open(f"{work}/{n}.npy.json")))
                                  for n in ("on_lattice", "off_lattice"))
h = on_side["voxel_size"]
assert off_side["voxel_size"] == h, "voxel size"
shift = [(o - p) / h for o, p in zip(off_side["origin"], on_side["origin"])]
assert all(abs(s - round(s)) < 1e-6 for s in shift), f"not on A's lattice: {shift}"
s = [int(round(v)) for v in shift]  # off's voxel 0 is on's voxel s
lo = [max(0, v) for v in s]
hi = [min(n, v + m) for n, m, v in zip(on.shape, off.shape, s)]
a = on[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
b = off[lo[0] - s[0]:hi[0] - s[0], lo[1] - s[1]:hi[1] - s[1], lo[2] - s[2]:hi[2] - s[2]]
near = np.abs(a) < 1.5 * h
worst = float(np.abs(a - b)[near].max()) / h
assert near.sum() > 1000 and worst < 0.3, f"{near.sum()} samples, worst {worst:.3f} voxels"
print(f"ok {worst:.3f}")
EOF_PY
)
[ "$RC" -eq 0 ] && [ "${verdict%% *}" = ok ] &&
    pass "csg of .vdb level sets on other lattices: on A's lattice, within ${verdict#ok } voxels" ||
    fail "csg of .vdb level sets on different lattices" "rc=$RC $verdict err=$ERR"
for op in union difference intersection; do
    run csg "$WORK/ball_a.obj" "$op" "$WORK/ball_b.obj" -r 40 -o "$WORK/balls_$op.obj"
    topology=$(obj_topology "$WORK/balls_$op.obj")
    [ "$RC" -eq 0 ] && [ "$topology" = "$closed_genus0" ] && ! grep -q '^warning' <<<"$OUT" &&
        pass "csg $op of overlapping spheres with the defaults is closed, manifold, genus 0" ||
        fail "csg $op of overlapping spheres" "rc=$RC $topology out=$OUT err=$ERR"
done
for op in union difference; do  # spot with its shifted copy: closed and manifold, any genus
    topology=$(obj_topology "$WORK/csg_$op.obj")
    [[ "$topology" == "border 0 non-manifold 0 oriented 1 vertex-manifold 1 euler "* ]] &&
        pass "csg $op of spot and its shifted copy is closed and manifold" ||
        fail "csg $op of spot and its shifted copy" "$topology"
done

# A grid the user places (--pad 0 here) that cuts the shape: warned about in the summary.
run sdf "$MESH" -r 24 --pad 0 -o "$WORK/cut.npy" --mesh "$WORK/cut.obj"
[ "$RC" -eq 0 ] && grep -q '^warning  the shape reaches the grid border' <<<"$OUT" &&
    [[ "$(obj_topology "$WORK/cut.obj")" != "border 0 "* ]] &&
    pass "a grid that cuts the shape is warned about (and its mesh is open)" ||
    fail "no warning for a grid that cuts the shape" "rc=$RC out=$OUT"

run mesh "$WORK/sdf.npy" -o "$WORK/remeshed.obj" --mesher marching-cubes
faces=$(obj_faces "$WORK/remeshed.obj")
[ "$RC" -eq 0 ] && [ "$faces" -gt 100 ] && pass "mesh of the sdf .npy: $faces faces" ||
    fail "mesh of the sdf .npy" "rc=$RC faces=$faces err=$ERR"

o="$WORK/err_field.obj"
expect_failure "csg with an unknown op" "$o" 'xor|op' csg "$MESH" xor "$WORK/spot_moved.obj" -o "$o"
expect_failure "sdf --band 0" "$WORK/err.npy" 'band' sdf "$MESH" -r 24 --band 0 -o "$WORK/err.npy"
expect_failure "sdf --band -2" "$WORK/err.npy" 'band' sdf "$MESH" -r 24 --band=-2 -o "$WORK/err.npy"
expect_failure "mesh of a missing file" "$o" 'no-such-field' mesh "$WORK/no-such-field.npy" -o "$o"
expect_failure "mesh of a field with grid options" "$o" 'grid options' \
    mesh "$WORK/sdf.npy" -r 24 -o "$o"

# ---- hostile .npy fields, occupancy inputs, output paths checked first ---------------------------
# write_npy PATH DESCR SHAPE [DATA_BYTES]: a version 1.0 .npy header (padded as numpy pads it)
# followed by DATA_BYTES zero bytes (default: none), and a valid sidecar.
write_npy() {
    python3 - "$@" <<'EOF_PY'
import struct, sys
path, descr, shape = sys.argv[1:4]
data = int(sys.argv[4]) if len(sys.argv) > 4 else 0
d = "{'descr': '%s', 'fortran_order': True, 'shape': %s, }" % (descr, shape)
d += " " * ((64 - (10 + len(d) + 1) % 64) % 64) + "\n"
with open(path, "wb") as f:
    f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(d)) + d.encode() + bytes(data))
with open(path + ".json", "w") as f:
    f.write('{"origin": [0, 0, 0], "voxel_size": 1}')
EOF_PY
}

# expect_quick_failure NAME OUTPUT PATTERN ARGS...: as expect_failure (OUTPUT is a file that must
# not appear), and also within 2 s, at most 200 MiB peak memory, and never naming a temporary
# file. For checks that must happen before loading or computing anything.
expect_quick_failure() {
    local name=$1 output=$2 pattern=$3
    shift 3
    local start end rss
    start=$(date +%s.%N)
    /usr/bin/time -f '%M' -o "$WORK/rss" "$OCLVOX" "$@" >"$WORK/stdout" 2>"$WORK/stderr"
    RC=$?
    end=$(date +%s.%N)
    ERR=$(cat "$WORK/stderr")
    rss=$(tail -n1 "$WORK/rss")
    local seconds leftovers
    seconds=$(python3 -c "print(round($end - $start, 2))")
    leftovers=$(find "$(dirname "$output")" -maxdepth 1 \( -name "$(basename "$output")" -o \
        -name "*.tmp-*" \) -newer "$WORK/stamp" 2>/dev/null)
    if [ "$RC" -ne 1 ]; then
        fail "$name" "exit code $RC: $ERR"
    elif ! grep -qiE "$pattern" <<<"$ERR" || grep -q '\.tmp-' <<<"$ERR"; then
        fail "$name" "stderr does not match '$pattern' or names a temporary file: $ERR"
    elif [ -n "$leftovers" ]; then
        fail "$name" "left output behind: $leftovers"
    elif python3 -c "import sys; sys.exit(not ($seconds > 2 or $rss > 204800))"; then
        fail "$name" "took $seconds s and $((rss / 1024)) MiB"
    else
        pass "$name ($seconds s, $((rss / 1024)) MiB: $(head -n1 <<<"$ERR"))"
    fi
}

if [ ! -x /usr/bin/time ]; then
    fail "/usr/bin/time exists (Debian package time, see scripts/install_deps.sh)"
else
    touch "$WORK/stamp"
    o="$WORK/hostile.obj"
    write_npy "$WORK/huge.npy" '<f4' '(1024, 1024, 1024)'
    expect_quick_failure "mesh of a 128-byte .npy claiming 1024^3 float32" "$o" \
        'huge\.npy.*needs 4294967296 bytes' mesh "$WORK/huge.npy" -o "$o"
    write_npy "$WORK/e15.npy" '<f4' '(1000000, 1000000, 1000)' 1024
    expect_quick_failure "mesh of a 1 KB .npy claiming 10^15 values" "$o" \
        'e15\.npy.*needs 4000000000000000 bytes' mesh "$WORK/e15.npy" -o "$o"
    write_npy "$WORK/digits.npy" '<f4' '(12345678901234567890, 2, 2)' 64
    expect_quick_failure "mesh of a .npy with a 20-digit axis" "$o" \
        'digits\.npy.*12345678901234567890.*exceeds' mesh "$WORK/digits.npy" -o "$o"
    write_npy "$WORK/dims.npy" '<f4' '(2, 3, 4)' 96
    echo '{"origin": [0, 0, 0], "voxel_size": 1, "dims": [4, 3, 2]}' >"$WORK/dims.npy.json"
    expect_quick_failure "mesh of a .npy whose sidecar dims disagree" "$o" \
        'dims\.npy\.json.*disagree' mesh "$WORK/dims.npy" -o "$o"
    echo '{"origin": [0, 0, 0], "voxel_size": "1"}' >"$WORK/dims.npy.json"
    expect_quick_failure "mesh of a .npy whose sidecar voxel_size is a string" "$o" \
        'dims\.npy\.json.*voxel_size' mesh "$WORK/dims.npy" -o "$o"

    # Output paths: each command refuses before loading, on a grid that would take long to
    # compute. A directory, a folder that cannot be written, the input under another name.
    mkdir "$WORK/adir.obj" "$WORK/adir.npy" "$WORK/adir.json"
    cp "$MESH" "$WORK/in.obj"
    big=(-r 2048)
    expect_quick_failure "voxelize -o a directory" "$WORK/adir.obj.x" "adir\.obj'.*directory" \
        voxelize "$MESH" "${big[@]}" -o "$WORK/adir.obj"
    expect_quick_failure "voxelize --stats-json a directory" "$WORK/v.binvox" \
        "adir\.json'.*directory" voxelize "$MESH" "${big[@]}" -o "$WORK/v.binvox" \
        --stats-json "$WORK/adir.json"
    expect_quick_failure "voxelize -o an unwritable folder" "$WORK/none" \
        "/proc/oclvox_out\.binvox'.*cannot be written" \
        voxelize "$MESH" "${big[@]}" -o /proc/oclvox_out.binvox
    expect_quick_failure "voxelize -o its own input (as ./in.obj)" "$WORK/none" \
        "in\.obj'.*is the input file" voxelize "$WORK/in.obj" "${big[@]}" -o "$WORK/./in.obj"
    expect_quick_failure "sdf -o a directory" "$WORK/none" "adir\.npy'.*directory" \
        sdf "$MESH" "${big[@]}" -o "$WORK/adir.npy"
    expect_quick_failure "sdf --mesh its own input" "$WORK/s.npy" "in\.obj'.*is the input file" \
        sdf "$WORK/in.obj" "${big[@]}" -o "$WORK/s.npy" --mesh "$WORK/./in.obj"
    expect_quick_failure "csg -o its second input" "$WORK/none" "in\.obj'.*is the input file" \
        csg "$MESH" union "$WORK/in.obj" "${big[@]}" -o "$WORK/./in.obj"
    expect_quick_failure "mesh -o a missing folder" "$WORK/missing/m.obj" "missing'.*not exist" \
        mesh "$MESH" "${big[@]}" -o "$WORK/missing/m.obj"
    expect_quick_failure "mesh -o its own input" "$WORK/none" "in\.obj'.*is the input file" \
        mesh "$WORK/in.obj" "${big[@]}" -o "$WORK/./in.obj"
    cmp -s "$MESH" "$WORK/in.obj" && pass "the input survives every refused run" ||
        fail "the input was modified"
fi

# The occupancy .npy voxelize writes is a field input: meshed exactly as a mesh input's voxels
# are (same grid, same occupancy_to_field), and its union with itself is itself.
run voxelize "$MESH" -r 20 --mode solid -q -o "$WORK/occ.npy"
run mesh "$WORK/occ.npy" --mesher surface-nets -o "$WORK/occ_mesh.obj"
occ_rc=$RC
grep -q 'occ.npy (occupancy)' <<<"$OUT" || occ_rc="summary: $OUT"
run mesh "$MESH" -r 20 --pad 0 --mesher surface-nets -q -o "$WORK/direct_mesh.obj"
if [ "$occ_rc" = 0 ] && [ "$RC" -eq 0 ] && [ "$(obj_faces "$WORK/occ_mesh.obj")" -gt 100 ] &&
    cmp -s "$WORK/occ_mesh.obj" "$WORK/direct_mesh.obj"; then
    pass "mesh of an occupancy .npy equals mesh of its mesh ($(obj_faces "$WORK/occ_mesh.obj") faces)"
else
    fail "mesh of an occupancy .npy" "rc=$occ_rc/$RC err=$ERR"
fi
run csg "$WORK/occ.npy" union "$WORK/occ.npy" --mesher surface-nets -q -o "$WORK/occ_union.obj"
[ "$RC" -eq 0 ] && cmp -s "$WORK/occ_union.obj" "$WORK/occ_mesh.obj" &&
    pass "csg of occupancy .npy files: A union A is A" || fail "csg of occupancy .npy" "rc=$RC err=$ERR"
expect_failure "csg of occupancy .npy files into a field" "$WORK/occ_union.npy" 'occupancy.*mesh' \
    csg "$WORK/occ.npy" union "$WORK/occ.npy" -o "$WORK/occ_union.npy"

# --cubic: centred (cuda_voxelizer) by default, --cubic=min is binvox's placement. Checked on the
# .binvox header against the sample's bounding box computed here: binvox maps the cube to
# [translate, translate + scale], so min has translate = box minimum and scale = longest side.
for anchor in centre min; do
    run voxelize "$MESH" -r 16 "--cubic=$anchor" -q -o "$WORK/cubic_$anchor.binvox"
    verdict=$(python3 - "$MESH" "$WORK/cubic_$anchor.binvox" "$anchor" <<'EOF_PY'
import sys
vs = [list(map(float, l.split()[1:4])) for l in open(sys.argv[1]) if l.startswith("v ")]
lo = [min(v[k] for v in vs) for k in range(3)]
hi = [max(v[k] for v in vs) for k in range(3)]
side = max(hi[k] - lo[k] for k in range(3))
header = open(sys.argv[2], "rb").read(200).split(b"data\n")[0].decode().split("\n")
t = [float(x) for x in next(l for l in header if l.startswith("translate")).split()[1:]]
s = float(next(l for l in header if l.startswith("scale")).split()[1])
want = lo if sys.argv[3] == "min" else [(lo[k] + hi[k] - side) / 2 for k in range(3)]
ok = abs(s - side) <= 1e-12 * side and all(abs(t[k] - want[k]) <= 1e-12 * side for k in range(3))
print("ok" if ok else "translate %s scale %s, expected %s and %s" % (t, s, want, side))
EOF_PY
)
    [ "$RC" -eq 0 ] && [ "$verdict" = ok ] && pass "--cubic=$anchor places the cube as documented" ||
        fail "--cubic=$anchor" "rc=$RC $verdict err=$ERR"
done
run voxelize "$MESH" -r 16 --cubic -q -o "$WORK/cubic_plain.binvox"
cmp -s "$WORK/cubic_plain.binvox" "$WORK/cubic_centre.binvox" && pass "--cubic is --cubic=centre" ||
    fail "--cubic differs from --cubic=centre"
expect_failure "--cubic=middle" "$WORK/cubic_x.binvox" 'cubic' \
    voxelize "$MESH" -r 16 --cubic=middle -o "$WORK/cubic_x.binvox"

# ---- --json and --stats-json on every command --------------------------------------------------
# stdout must be exactly one JSON document (python3 -m json.tool refuses anything else), with the
# command's name and the keys a program needs.
json_keys() {  # FILE KEY...: "ok" or the keys missing
    python3 - "$@" <<'EOF_PY'
import json, sys
doc = json.load(open(sys.argv[1]))
missing = []
for path in sys.argv[2:]:
    value = doc
    for key in path.split("."):
        if not isinstance(value, dict) or key not in value:
            missing.append(path)
            break
        value = value[key]
print("ok" if not missing else "missing " + " ".join(missing))
EOF_PY
}
common_keys=(oclvox_version command inputs outputs backend device grid.dims grid.voxel_size
    grid.origin seconds.total warnings)
json_case() {  # NAME, command, expected extra keys (space-separated), oclvox arguments...
    local name=$1 command=$2 extra=$3
    shift 3
    run "$command" "$@" --json
    printf '%s' "$OUT" >"$WORK/run.json"
    local keys
    if [ "$RC" -ne 0 ] || ! python3 -m json.tool "$WORK/run.json" >/dev/null 2>&1; then
        fail "$name --json: one JSON document on stdout" "rc=$RC out=${OUT:0:300} err=$ERR"
        return
    fi
    # shellcheck disable=SC2086
    keys=$(json_keys "$WORK/run.json" $extra)
    if [ "$(json_field "$WORK/run.json" command)" = "$command" ] && [ "$keys" = ok ]; then
        pass "$name --json: one JSON document with the expected keys"
    else
        fail "$name --json keys" "$keys; command=$(json_field "$WORK/run.json" command)"
    fi
}
json_case "devices" devices "devices"
json_case "voxelize" voxelize "${common_keys[*]} voxels_set seconds.voxelize seconds.kernels mode test" \
    "$MESH" -r 24 -o "$WORK/json.npy"
python3 - "$WORK/run.json" <<'EOF_PY' && pass "voxelize --json: the voxelize phase's parts add up to it" ||
import json, sys
s = json.load(open(sys.argv[1]))["seconds"]
parts = sum(s[k] for k in ("binning", "upload", "kernels", "download", "other"))
sys.exit(not (min(s[k] for k in ("binning", "upload", "kernels", "download", "other")) >= 0
              and abs(parts - s["voxelize"]) <= 1e-6 + 1e-9 * s["voxelize"]))
EOF_PY
    fail "voxelize --json parts of the voxelize phase" "$(cat "$WORK/run.json")"
[ "$(json_field "$WORK/run.json" voxels_set)" = "$(npy_ones "$WORK/json.npy")" ] &&
    pass "voxelize --json voxels_set equals the ones in the .npy" ||
    fail "voxelize --json voxels_set" "$(json_field "$WORK/run.json" voxels_set)"
json_case "sdf" sdf "${common_keys[*]} band seconds.field mesh.triangles border_samples_inside" \
    "$MESH" -r 20 -o "$WORK/json_sdf.npy" --mesh "$WORK/json_sdf.obj"
[ "$(json_field "$WORK/run.json" mesh.triangles)" = "$(obj_faces "$WORK/json_sdf.obj")" ] &&
    pass "sdf --json mesh.triangles equals the faces of the OBJ" ||
    fail "sdf --json mesh.triangles" "$(json_field "$WORK/run.json" mesh.triangles)"
json_case "csg" csg "${common_keys[*]} op mesher mesh.triangles" \
    "$MESH" difference "$WORK/spot_moved.obj" -r 20 -o "$WORK/json_csg.obj"
json_case "mesh" mesh "${common_keys[*]} iso mesher mesh.vertices" \
    "$WORK/sdf.npy" -o "$WORK/json_mesh.ply"
for command in devices voxelize sdf csg mesh; do
    case $command in
    devices) args=() ;;
    voxelize) args=("$MESH" -r 16 -q -o "$WORK/sj.binvox") ;;
    sdf) args=("$MESH" -r 16 -q -o "$WORK/sj.vdb") ;;
    csg) args=("$MESH" union "$WORK/spot_moved.obj" -r 16 -q -o "$WORK/sj.stl") ;;
    mesh) args=("$MESH" -r 16 -q -o "$WORK/sj.obj") ;;
    esac
    run "$command" "${args[@]}" --stats-json "$WORK/sj_$command.json"
    [ "$RC" -eq 0 ] && [ "$(json_field "$WORK/sj_$command.json" command)" = "$command" ] &&
        pass "$command --stats-json writes the run's JSON" ||
        fail "$command --stats-json" "rc=$RC err=$ERR"
done

# ---- typos get the closest valid name -----------------------------------------------------------
typo_case() {  # expected suggestion, arguments...
    local want=$1
    shift
    run "$@"
    [ "$RC" -eq 2 ] && grep -qF "did you mean '$want'?" <<<"$ERR" &&
        pass "typo '$*' suggests '$want'" || fail "typo '$*'" "rc=$RC err=$ERR"
}
typo_case voxelize voxelise "$MESH" -o "$WORK/t.binvox"
typo_case devices devises
typo_case --resolution voxelize "$MESH" --resolutoin 32 -o "$WORK/t.binvox"
typo_case --band sdf "$MESH" --bnad 2 -o "$WORK/t.npy"
typo_case --mesher csg "$MESH" union "$MESH" --meshr=surface-nets -o "$WORK/t.obj"
typo_case --stats-json mesh "$MESH" --stat-json x.json -o "$WORK/t.obj"

# ---- - as input (stdin) and output (stdout) -----------------------------------------------------
# A binary STL of the sample written here, so stdin must be recognised as STL by its size rule.
python3 - "$MESH" "$WORK/spot_binary.stl" <<'EOF_PY'
import struct, sys
vs, fs = [], []
for line in open(sys.argv[1]):
    w = line.split()
    if w and w[0] == "v": vs.append(tuple(map(float, w[1:4])))
    if w and w[0] == "f": fs.append([int(x.split("/")[0]) - 1 for x in w[1:]])
tris = [(f[0], f[i], f[i + 1]) for f in fs for i in range(1, len(f) - 1)]
with open(sys.argv[2], "wb") as out:
    out.write(b"solid but binary".ljust(80, b" ") + struct.pack("<I", len(tris)))
    for t in tris:
        out.write(struct.pack("<12fH", 0, 0, 0, *[c for i in t for c in vs[i]], 0))
EOF_PY
"$OCLVOX" voxelize "$MESH" -r 24 -q -o "$WORK/file.binvox"
"$OCLVOX" voxelize - -r 24 -o - --output-format binvox <"$MESH" >"$WORK/piped.binvox" \
    2>"$WORK/stderr"
RC=$?
[ "$RC" -eq 0 ] && cmp -s "$WORK/piped.binvox" "$WORK/file.binvox" &&
    grep -q '^output   - (stdout)' "$WORK/stderr" &&
    pass "OBJ on stdin to .binvox on stdout equals the file run; summary on stderr" ||
    fail "stdin/stdout .binvox" "rc=$RC $(cat "$WORK/stderr")"
"$OCLVOX" voxelize "$WORK/spot_binary.stl" -r 24 -q -o "$WORK/stl_file.npy"
run voxelize - -r 24 -q -o "$WORK/stl_piped.npy" <"$WORK/spot_binary.stl"
[ "$RC" -eq 0 ] && cmp -s "$WORK/stl_file.npy" "$WORK/stl_piped.npy" &&
    pass "binary STL on stdin is recognised without --input-format" ||
    fail "binary STL on stdin" "rc=$RC err=$ERR"
# (A temporary folder of its own, so that other programs' files cannot be taken for its leftovers.)
mkdir "$WORK/staging"
TMPDIR="$WORK/staging" run voxelize - -r 24 -q --input-format obj -o "$WORK/stl_as_obj.npy" \
    <"$WORK/spot_binary.stl"
[ "$RC" -eq 1 ] && grep -q 'stdin' <<<"$ERR" && [ -z "$(ls -A "$WORK/staging")" ] &&
    pass "a wrong --input-format fails naming stdin, nothing staged left" ||
    fail "wrong --input-format" "rc=$RC err=$ERR"
"$OCLVOX" mesh - -r 20 -o - --output-format obj --mesher surface-nets <"$MESH" \
    >"$WORK/piped_mesh.obj" 2>/dev/null
"$OCLVOX" mesh "$MESH" -r 20 -q -o "$WORK/file_mesh.obj" --mesher surface-nets
cmp -s "$WORK/piped_mesh.obj" "$WORK/file_mesh.obj" && pass "mesh from stdin to stdout equals the file run" ||
    fail "mesh stdin/stdout"
expect_failure "-o - as .npy (a sidecar cannot stream)" "$WORK/none" 'sidecar' \
    voxelize "$MESH" -r 16 -o - --output-format npy
[ "$RC" -eq 2 ] && pass "-o - as .npy is a usage error" || fail "-o - npy exit" "rc=$RC"
expect_failure "-o - without --output-format" "$WORK/none" 'output-format' voxelize "$MESH" -o -
expect_failure "--json with -o -" "$WORK/none" 'json' \
    voxelize "$MESH" -o - --output-format binvox --json
expect_failure "garbage on stdin" "$WORK/none" 'input-format' voxelize - -o "$WORK/g.binvox" \
    <"$WORK/garbage.obj"

# ---- --preview PNG ------------------------------------------------------------------------------
# Decoded here from the PNG specification (zlib and the five row filters, no image library), and
# compared pixel by pixel with the max-projections of the .npy the same run wrote.
check_preview() {  # PNG, NPY (uint8 occupancy, or float field: inside is < 0)
    python3 - "$@" <<'EOF_PY'
import ast, json, struct, sys, zlib
import numpy as np
png = open(sys.argv[1], "rb").read()
assert png[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
at, idat, text = 8, b"", {}
while at < len(png):
    length, kind = struct.unpack(">I4s", png[at:at + 8])
    body = png[at + 8:at + 8 + length]
    if kind == b"IHDR":
        width, height, depth, colour = struct.unpack(">IIBB", body[:10])
        assert (depth, colour) == (8, 0), "expected 8-bit grey"
    elif kind == b"IDAT":
        idat += body
    elif kind == b"tEXt":
        key, value = body.split(b"\0", 1)
        text[key.decode()] = value.decode("latin1")
    at += 12 + length
raw, rows, previous = zlib.decompress(idat), [], [0] * width
for r in range(height):
    line = raw[r * (width + 1):(r + 1) * (width + 1)]
    f, row = line[0], []
    for i, x in enumerate(line[1:]):
        a = row[i - 1] if i else 0
        b, c = previous[i], previous[i - 1] if i else 0
        p = a + b - c
        pred = [0, a, b, (a + b) // 2,
                a if abs(p - a) <= min(abs(p - b), abs(p - c)) else (b if abs(p - b) <= abs(p - c) else c)][f]
        row.append((x + pred) & 255)
    rows.append(row)
    previous = row
image = np.array(rows, dtype=np.uint8)
layout = json.loads(text["oclvox-layout"])
data = open(sys.argv[2], "rb").read()
hlen = struct.unpack("<H", data[8:10])[0]
header = ast.literal_eval(data[10:10 + hlen].decode("latin1"))
values = np.frombuffer(data[10 + hlen:], dtype=np.dtype(header["descr"]))
values = values.reshape(header["shape"], order="F" if header["fortran_order"] else "C")
inside = values > 0 if values.dtype == np.uint8 else values < 0
s, d = layout["pixels_per_voxel"], layout["voxels_per_pixel"]
assert d == 1, "test grids are small"
for axis, panel in enumerate(layout["panels"]):
    expected = inside.any(axis=axis)  # (horizontal, vertical): the two other axes in order
    expected = np.repeat(np.repeat(expected, s, axis=0), s, axis=1).T[::-1]  # rows: up first
    got = image[panel["top"]:panel["top"] + panel["height"], panel["left"]:panel["left"] + panel["width"]]
    if got.shape != expected.shape or not np.array_equal(got == 255, expected):
        print("panel along %s differs: %s vs %s" % (panel["along"], got.shape, expected.shape)); sys.exit()
    if expected.all() or not expected.any():
        print("panel along %s is uniform" % panel["along"]); sys.exit()
bar = layout["scale_bar"]
lit = image[bar["top"] + 1, :] == 255
length = layout["scale_bar"]["length"]
pixel = float(json.load(open(sys.argv[2] + ".json"))["voxel_size"]) / s
if lit.sum() != bar["pixels"] or abs(bar["pixels"] * pixel - length) > pixel:
    print("scale bar %d pixels for %g units at %g per pixel" % (lit.sum(), length, pixel)); sys.exit()
print("ok")
EOF_PY
}
run voxelize "$MESH" -r 24 --mode solid -q -o "$WORK/preview.npy" --preview "$WORK/preview.png"
verdict=$(check_preview "$WORK/preview.png" "$WORK/preview.npy" 2>&1)
[ "$RC" -eq 0 ] && [ "$verdict" = ok ] &&
    pass "voxelize --preview: the PNG's three panels are the .npy's max-projections" ||
    fail "voxelize --preview" "rc=$RC $verdict $ERR"
run sdf "$MESH" -r 20 -q -o "$WORK/preview_sdf.npy" --preview "$WORK/preview_sdf.png"
verdict=$(check_preview "$WORK/preview_sdf.png" "$WORK/preview_sdf.npy" 2>&1)
[ "$RC" -eq 0 ] && [ "$verdict" = ok ] &&
    pass "sdf --preview: the PNG's panels are the field's inside projected" ||
    fail "sdf --preview" "rc=$RC $verdict $ERR"
# The narrow band's preview is drawn from the sparse field (inside voxels and leaves), the full
# grid's from its meshing view, gathered from its slabs: the same inside, so the same image.
"$OCLVOX" sdf "$MESH" -r 20 -q --full -o "$WORK/preview_full.npy" --preview "$WORK/preview_full.png"
cmp -s "$WORK/preview_sdf.png" "$WORK/preview_full.png" &&
    pass "sdf --preview of the sparse band equals the full grid's byte for byte" ||
    fail "sdf --preview band vs full grid" "the PNGs differ"
expect_failure "--preview not a .png" "$WORK/p.jpg" 'png' \
    voxelize "$MESH" -r 16 -o "$WORK/p.binvox" --preview "$WORK/p.jpg"

# ---- Ctrl-C -------------------------------------------------------------------------------------
# A run that computes for several seconds on PoCL, reporting progress often, gets one SIGINT after
# 1 s, sent to its whole process group as a terminal's Ctrl-C is (job control gives the run its
# own group). It must stop through its progress callback (the message says so; the watcher that
# ends a run still going after 1.5 s prints none), with exit 130 and no output; a watchdog kills
# it if it ignores the signal.
sigint_test() {  # name, output, arguments...
    local name=$1 output=$2
    shift 2
    (
        set -m
        "$OCLVOX" "$@" >"$WORK/stdout" 2>"$WORK/stderr" &
        pid=$!
        (sleep 30 && kill -KILL -- "-$pid") >/dev/null 2>&1 &
        watchdog=$!
        sleep 1
        kill -INT -- "-$pid"
        wait "$pid"
        rc=$?
        kill -- "-$watchdog" 2>/dev/null
        exit $rc
    )
    RC=$?
    ERR=$(cat "$WORK/stderr")
    if [ "$RC" -eq 130 ] && grep -q 'cancelled' <<<"$ERR" && [ ! -e "$output" ] &&
        [ -z "$(find "$WORK" -name "*$(basename "$output")*")" ]; then
        pass "SIGINT cancels $name: exit 130, 'cancelled', no output"
    else
        fail "SIGINT cancels $name" "rc=$RC err=$ERR"
    fi
}
# (Runs long enough that the signal comes while they work, on 2 CPU cores and on a GPU: the
# voxelization about 6 s uncancelled on 2 cores, where 2048^3 to .binvox had come to finish within
# the second; the full-grid fields at 768^3, which take minutes on 2 cores, as 256^3 took under 2 s
# there and under half a second on an H200. Written as .vdb, which needs no free space checked for
# a dense file up front.)
sigint_test voxelize "$WORK/cancel.vdb" \
    voxelize "$MESH" -r 8192 --device-memory 1 -o "$WORK/cancel.vdb"
sigint_test sdf "$WORK/cancel_sdf.vdb" sdf "$MESH" -r 768 --full -o "$WORK/cancel_sdf.vdb"
sigint_test csg "$WORK/cancel_csg.vdb" csg "$MESH" union "$MESH" -r 768 --full \
    -o "$WORK/cancel_csg.vdb"

echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ]
