#!/usr/bin/env bash
# Whole-process cost of writing voxel outputs: bunny00 through the CLI, with the CLI's own
# voxelize and write times (wall clock), /usr/bin/time's user+system CPU time and peak RSS, as
# Markdown table rows. On a shared machine the CPU column is the steadier one.
# Usage: bash bench/writers.sh [OCLVOX_BINARY] [CASE...]
#   CASE is NAME (see below); default: all cases that fit in this machine's memory.
#   OCLVOX_BINARY defaults to build/oclvox (run an older build to compare before/after).
set -euo pipefail
cd "$(dirname "$0")/.."
oclvox=${1:-build/oclvox}
shift || true
mesh=${OCLVOX_MESH_DIR:-../shared/data/meshes}/bunny00.off
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# name | resolution | output extension | extra options
cases=(
  "binvox-1024|1024|binvox|"
  "binvox-2048|2048|binvox|"
  "binvox-solid-1024|1024|binvox|--mode solid --inside parity"
  "npy-512|512|npy|"
  "npy-solid-512|512|npy|--mode solid --inside parity"
  "npy-1536|1536|npy|"
  "vdb-4096|4096|vdb|"
  "vdb-8192|8192|vdb|"
  "obj-512|512|obj|"
  "ply-512|512|ply|"
  "stl-512|512|stl|"
  "obj-solid-512|512|obj|--mode solid --inside parity"
  "ply-solid-512|512|ply|--mode solid --inside parity"
  "stl-solid-512|512|stl|--mode solid --inside parity"
  "vox-512|512|vox|"
  "vox-solid-512|512|vox|--mode solid --inside parity"
)
wanted=("$@")

commit=$(git -C "$(dirname "$oclvox")" rev-parse --short HEAD 2>/dev/null || echo unknown)
echo "machine: $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB RAM, load $(cut -d' ' -f1 /proc/loadavg); binary $oclvox (commit $commit)"
echo
echo "| case | grid | voxels set | voxelize s | write s | whole process s | process CPU s | peak RSS MB |"
echo "|---|---|---|---|---|---|---|---|"
for spec in "${cases[@]}"; do
  IFS='|' read -r name res ext extra <<<"$spec"
  if [ ${#wanted[@]} -gt 0 ] && [[ ! " ${wanted[*]} " =~ " $name " ]]; then continue; fi
  log="$out/$name.log"
  # shellcheck disable=SC2086
  /usr/bin/time -f "PEAK_RSS_KB %M WALL_S %e CPU_S %U %S" "$oclvox" voxelize "$mesh" -r "$res" $extra \
    -o "$out/$name.$ext" --stats >"$log" 2>&1 || { echo "| $name | failed: $(tail -1 "$log") |"; continue; }
  grid=$(awk '/^grid/{print $2}' "$log")
  set_=$(awk '/^voxels /{print $2}' "$log")
  vox=$(awk '$1=="voxelize"{print $2}' "$log")
  write=$(awk '$1=="write"{print $2}' "$log")
  wall=$(awk '/WALL_S/{print $4}' "$log")
  rss=$(awk '/PEAK_RSS_KB/{printf "%d", $2/1024}' "$log")
  cpu=$(awk '/PEAK_RSS_KB/{printf "%.1f", $6 + $7}' "$log")
  echo "| bunny00 surface${extra:+ ($extra)} -> .$ext | $grid | $set_ | $vox | $write | $wall | $cpu | $rss |"
  rm -f "$out/$name.$ext" "$out/$name.$ext.json"
done
