#!/usr/bin/env bash
# Configures and builds oclvox (Release) in ./build. Extra arguments go to the CMake configure.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build build -j"$(nproc)"
