#!/usr/bin/env bash
# Side-by-side voxelization timings: oclvox against the tools users would otherwise pick, same
# meshes and resolutions, in one run. Each figure is the voxelization call alone (no loading, no
# writing), in seconds, the minimum of REPEAT runs; with WHOLE=1 it is the whole process instead,
# loading the mesh and writing the result (oclvox and cuda_voxelizer a .binvox, naive_tribox the
# only file it writes, its dense raw bytes).
#
#   bash bench/peers.sh [RES...]              (default: 256 1024)
#   MODE=solid bash bench/peers.sh [RES...]   parity solids of closed meshes: oclvox --mode solid
#                                             (parity), naive_tribox --mode solid (parity along x)
#   WHOLE=1 bash bench/peers.sh [RES...]      whole processes writing their file (issue 8's
#                                             target: oclvox 5x faster than both peers at 1024)
#
# Peers are optional; the script says which it found:
#   NAIVE_TRIBOX    path of naive_tribox (plain OpenMP 13-axis SAT over each triangle's bbox;
#                   build: g++ -O3 -march=native -fopenmp -o naive_tribox naive_tribox.cpp),
#                   else `naive_tribox` on PATH
#   CUDA_VOXELIZER  path of cuda_voxelizer, else `cuda_voxelizer` on PATH; run with -cpu unless
#                   CUDA_VOXELIZER_GPU=1
# Other settings: OCLVOX (default build/oclvox), OCLVOX_DEVICE (device selector), MESHES (mesh
# files, default bunny, buildings and motorBike from ../shared/data/meshes; for MODE=solid the
# closed bunny00 and spot), REPEAT (default 3), THREADS (naive_tribox threads, default: all cores).
# naive_tribox reads OBJ only: other meshes (OFF) are converted for it first. cuda_voxelizer's
# -solid crashes or is wrong on most meshes, so it is left out of MODE=solid.
#
# Grids: oclvox and naive_tribox fit RES voxels to the longest side of the mesh's bounding box;
# cuda_voxelizer pads the box to a cube first. So the grids agree in voxel size, not in origin.
set -euo pipefail
cd "$(dirname "$0")/.."

resolutions=("$@")
[ ${#resolutions[@]} -gt 0 ] || resolutions=(256 1024)
mesh_dir=${OCLVOX_MESH_DIR:-../shared/data/meshes}
mode=${MODE:-surface}
whole=${WHOLE:-0}
case "$mode" in
surface) default_meshes="$mesh_dir/stanford-bunny.obj $mesh_dir/buildings.obj $mesh_dir/motorBike.obj" ;;
solid) default_meshes="$mesh_dir/bunny00.off $mesh_dir/spot.obj" ;;
*) echo "peers.sh: MODE must be surface or solid, not $mode" >&2; exit 2 ;;
esac
read -r -a meshes <<< "${MESHES:-$default_meshes}"
repeat=${REPEAT:-3}
threads=${THREADS:-$(nproc)}
oclvox=${OCLVOX:-build/oclvox}
device=()
[ -z "${OCLVOX_DEVICE:-}" ] || device=(--device "$OCLVOX_DEVICE")

find_tool() {  # find_tool ENV_VALUE NAME: prints the path, or nothing
    if [ -n "$1" ]; then
        if [ -x "$1" ]; then echo "$1"; else echo "peers.sh: $1 is not executable" >&2; fi
    else
        command -v "$2" || true
    fi
}
naive=$(find_tool "${NAIVE_TRIBOX:-}" naive_tribox)
cuda=$(find_tool "${CUDA_VOXELIZER:-}" cuda_voxelizer)
cuda_flag=-cpu
[ "${CUDA_VOXELIZER_GPU:-0}" = 1 ] && cuda_flag=
[ "$mode" = surface ] || cuda=

[ -x "$oclvox" ] || { echo "peers.sh: $oclvox not found; build first (scripts/build.sh)" >&2; exit 1; }
echo "mode:           $mode ($([ "$whole" = 1 ] && echo "whole processes writing their file" || echo "the voxelization call alone"))"
echo "oclvox:         $oclvox (${OCLVOX_DEVICE:-default device})"
echo "naive_tribox:   ${naive:-not found (set NAIVE_TRIBOX)}${naive:+ ($threads threads)}"
echo "cuda_voxelizer: ${cuda:-not found (set CUDA_VOXELIZER)}${cuda:+ (${cuda_flag:-GPU})}"
echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores;" \
    "commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown); min of $repeat runs"
echo

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

min_of() { sort -g | head -n1; }

wall_seconds() {  # command...: its wall time in seconds (its output discarded)
    local start end
    start=$(date +%s.%N)
    "$@" > /dev/null 2>&1
    end=$(date +%s.%N)
    awk -v a="$start" -v b="$end" 'BEGIN { printf "%.3f\n", b - a }'
}

oclvox_seconds() {  # mesh res: the "voxelize" phase of --stats, or (WHOLE=1) the whole process
    for _ in $(seq "$repeat"); do
        if [ "$whole" = 1 ]; then
            wall_seconds "$oclvox" voxelize "${device[@]}" "$1" -r "$2" --mode "$mode" \
                -o "$work/out.binvox" --quiet
        else
            "$oclvox" voxelize "${device[@]}" "$1" -r "$2" --mode "$mode" -o "$work/out.binvox" \
                --stats 2>&1 | awk '$1 == "voxelize" { print $2 }'
        fi
    done | min_of
    rm -f "$work/out.binvox"
}

naive_seconds() {
    local mesh=$1
    case "$mesh" in
    *.obj) ;;
    *.off)  # OFF to OBJ: vertices, then faces with 1-based indices
        mesh="$work/$(basename "$1" .off).obj"
        awk 'NR == 1 { next } !counts && NF >= 3 { nv = $1; counts = 1; next }
             counts && v < nv && NF >= 3 { print "v", $1, $2, $3; v++; next }
             counts && v == nv && NF >= 4 { s = "f"; for (i = 2; i <= $1 + 1; i++) s = s " " $i + 1; print s }' \
            "$1" > "$mesh" ;;
    *) echo "peers.sh: naive_tribox reads OBJ or (converted) OFF, not $1" >&2; return ;;
    esac
    if [ "$whole" = 1 ]; then
        for _ in $(seq "$repeat"); do
            wall_seconds "$naive" "$mesh" "$2" --threads "$threads" --mode "$mode" \
                --out "$work/out.raw"
        done | min_of
        rm -f "$work/out.raw"
        return
    fi
    "$naive" "$mesh" "$2" --threads "$threads" --repeat "$repeat" --mode "$mode" |
        sed -n 's/.* t_vox=\([^ ]*\).*/\1/p'
}

cuda_seconds() {  # cuda_voxelizer writes beside its input: work on a copy
    local copy="$work/$(basename "$1")"
    cp "$1" "$copy"
    for _ in $(seq "$repeat"); do
        if [ "$whole" = 1 ]; then
            # shellcheck disable=SC2086
            wall_seconds "$cuda" -f "$copy" -s "$2" -o binvox $cuda_flag
        else
            # shellcheck disable=SC2086
            "$cuda" -f "$copy" -s "$2" -o binvox $cuda_flag 2>&1 |
                sed -n 's/.*voxelization time: *\([0-9.]*\) *ms.*/\1/p' | awk '{ print $1 / 1000 }'
        fi
    done | min_of
    rm -f "$copy"*
}

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (a > 0 && b > 0) printf "%.2f", b / a; else print "-" }'; }

echo "| mesh | res | oclvox s | naive_tribox s | cuda_voxelizer s | naive / oclvox | cuda_voxelizer / oclvox |"
echo "|---|---:|---:|---:|---:|---:|---:|"
for mesh in "${meshes[@]}"; do
    for res in "${resolutions[@]}"; do
        ours=$(oclvox_seconds "$mesh" "$res")
        n=-
        c=-
        [ -z "$naive" ] || n=$(naive_seconds "$mesh" "$res")
        [ -z "$cuda" ] || c=$(cuda_seconds "$mesh" "$res")
        echo "| $(basename "$mesh") | $res | $ours | ${n:--} | ${c:--} | $(ratio "$ours" "${n:-0}") |" \
            "$(ratio "$ours" "${c:-0}") |"
    done
done
