#!/usr/bin/env bash
# The README's second command (and CI's): installs what is missing, builds everything and runs
# the whole test suite under PoCL.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh -DOCLVOX_BUILD_TESTS=ON
cd build
ctest --output-on-failure -j"$(nproc)" --timeout 900
