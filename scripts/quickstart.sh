#!/usr/bin/env bash
# The README's first command: installs what is missing, builds, lists the OpenCL devices and
# voxelizes the bundled sample (samples/spot.obj) to out/spot.binvox with a run summary.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh -DOCLVOX_BUILD_TESTS=OFF
mkdir -p out
./build/oclvox devices
./build/oclvox voxelize samples/spot.obj -r 128 -o out/spot.binvox --stats
