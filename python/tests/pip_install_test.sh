#!/usr/bin/env bash
# `pip install .` into a fresh virtual environment, then the Python tests against the installed
# package, run from outside the source tree. Usage: pip_install_test.sh SOURCE_DIR [PYTHON]
# (OCLVOX_CLI and OCLVOX_SAMPLE_DIR pass through to the tests, as for the CTest test `python`).
# The virtual environment sees the system's numpy and pytest (Debian's python3-numpy and
# python3-pytest); pip fetches the build requirements (scikit-build-core, pybind11) from PyPI.
set -euo pipefail
source_dir=$(cd "$1" && pwd)
python=${2:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

start=$(date +%s)
"$python" -m venv --system-site-packages "$work/venv"
export CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-$(nproc)}
command -v ccache >/dev/null && export CMAKE_CXX_COMPILER_LAUNCHER=ccache
"$work/venv/bin/python" -m pip install --quiet --disable-pip-version-check "$source_dir"
echo "pip install took $(($(date +%s) - start)) s of wall-clock time"

cd "$work"
# The module imported is the installed one, not a copy in the source or build tree.
"$work/venv/bin/python" - "$work/venv" <<'PY'
import pathlib, sys
import oclvox
where = pathlib.Path(oclvox.__file__).resolve()
assert where.is_relative_to(pathlib.Path(sys.argv[1]).resolve()), where
print("imported", where)
PY
"$work/venv/bin/python" -m pytest -q -p no:cacheprovider \
    --rootdir "$work" "$source_dir/python/tests"
