#!/usr/bin/env bash
# Installs the Debian packages oclvox needs to build, test and run on PoCL's CPU device.
# Installs only what is missing, so a prepared machine costs nothing.
# `--fuzz` adds what scripts/fuzz.sh needs (clang, its libFuzzer/sanitizer runtimes, the symbolizer).
set -euo pipefail

packages=(
  cmake g++ make python3 time libpng-dev
  ocl-icd-opencl-dev opencl-c-headers opencl-clhpp-headers pocl-opencl-icd clinfo
  libassimp-dev nlohmann-json3-dev libcli11-dev
  libopenvdb-dev libboost-iostreams-dev
  python3-openvdb python3-numpy
  libgtest-dev libgmock-dev
  python3-dev python3-venv python3-numpy python3-pytest pybind11-dev
  python3-dask python3-distributed
)
fuzz_packages=(clang libclang-rt-14-dev llvm)
[ "${1:-}" = "--fuzz" ] && packages+=("${fuzz_packages[@]}")

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "oclvox: installing ${missing[*]}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
