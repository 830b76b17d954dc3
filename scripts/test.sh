#!/usr/bin/env bash
# The README's second command (and CI's): installs what is missing, builds everything and runs
# the whole test suite under PoCL.
set -euo pipefail
cd "$(dirname "$0")/.."
# The Python package is built into build/python with Debian's python3, whose numpy and pytest
# install_deps.sh installs; CTest runs pytest on it (tests `python` and `python_pip_install`).
bash scripts/build.sh -DOCLVOX_BUILD_TESTS=ON -DOCLVOX_BUILD_PYTHON=ON \
    -DPython_EXECUTABLE=/usr/bin/python3
cd build
ctest --output-on-failure -j"$(nproc)" --timeout 900
