#!/usr/bin/env bash
# Runs the standard benchmark set and writes bench/RESULTS.md (Markdown table, machine, device,
# driver, commit) and bench/results.json. Usage: bash bench/run.sh [--device SEL] [RES...]
set -euo pipefail
cd "$(dirname "$0")/.."
device=()
if [ "${1:-}" = "--device" ]; then device=(--device "$2"); shift 2; fi
resolutions=("$@")
[ ${#resolutions[@]} -gt 0 ] || resolutions=(256 512 1024 2048)
meshes=../shared/data/meshes
bash scripts/build.sh -DOCLVOX_BUILD_TESTS=OFF >/dev/null
commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
out=bench/RESULTS.md.tmp
{
  echo "# oclvox benchmark results"
  echo
  echo "Run on $(date -u +%Y-%m-%d) with \`bash bench/run.sh ${*:-}\` ($(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB RAM)."
  echo
  build/bench/oclvox_bench "${device[@]}" --commit "$commit" --json bench/results.json \
    "$meshes/spot.obj" "$meshes/bunny00.off" "$meshes/TR12J_OCC.stl" "$meshes/motorBike.obj" \
    "$meshes/buildings.obj" -- "${resolutions[@]}"
  echo
  echo "## 4096^3 bunny (dense bits would be 8 GiB)"
  echo
  /usr/bin/time -f "peak RSS of the whole process: %M KiB" build/bench/oclvox_bench "${device[@]}" \
    --repeat 1 --commit "$commit" "$meshes/bunny00.off" -- 4096 2>&1 | grep -v '^machine\|^device\|^commit'
  echo
  echo "# Solid, SDF, meshing and CSG"
  echo
  build/bench/oclvox_bench_pipeline "${device[@]}" --commit "$commit" \
    "$meshes/spot.obj" "$meshes/bunny00.off" -- 64 128
} > "$out"
mv "$out" bench/RESULTS.md
cat bench/RESULTS.md
