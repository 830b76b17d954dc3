#!/usr/bin/env bash
# The Python package's tests on the lent GPU machine, which has neither Debian's python3.11 nor
# numpy, pytest or Dask. Three parts:
#   bash scripts/gpu_python.sh pack   here, after scripts/build.sh with -DOCLVOX_BUILD_PYTHON=ON and
#                                     ../shared/tools/gpu/pack.sh: adds OpenVDB's module
#                                     (liboclvox_vdb.so) to pack.sh's bundle, writes .gpu/python.tar.xz
#                                     (python3.11 with its standard library, Debian's numpy, pytest
#                                     and Dask, the libraries they link, our built package and its
#                                     tests; about 19 MB, so .gpu stays within the 64 MiB a call
#                                     carries)
#   bash scripts/gpu_python.sh run    there, after `source .gpu/env.sh` (which sets $B): unpacks it
#                                     and runs pytest on the GPU (OCLVOX_DEVICE as env.sh set it);
#                                     extra arguments go to pytest
#   bash scripts/gpu_python.sh unpack there: only unpacks it, and prints the folder whose
#                                     bin/python3 runs it (scripts/gpu_check.sh puts it on PATH for
#                                     the CLI tests, whose checks read files with numpy)
# For example: run(command="source .gpu/env.sh && bash scripts/gpu_python.sh run", carry=[".gpu"])
# python3-openvdb is left out (it links OpenVDB AX and LLVM, over 100 MB): its one test skips.
set -euo pipefail
root=$(git rev-parse --show-toplevel 2>/dev/null || pwd)
cd "$root"

pack() {
    local build=${1:-build} stage
    [[ -d $build/python/oclvox ]] || { echo "gpu_python.sh: no $build/python/oclvox (build with -DOCLVOX_BUILD_PYTHON=ON)" >&2; exit 2; }
    stage=$(mktemp -d)
    local py=$stage/py
    mkdir -p "$py/bin" "$py/lib/python3.11" "$py/dist" "$py/so"
    cp /usr/bin/python3.11 "$py/bin/"
    tar -C /usr/lib/python3.11 --exclude=test --exclude=idlelib --exclude=tkinter \
        --exclude=lib2to3 --exclude=ensurepip --exclude='config-3.11*' --exclude=pydoc_data \
        --exclude=__pycache__ --exclude=dist-packages -cf - . | tar -C "$py/lib/python3.11" -xf -
    tar -C /usr/lib/python3/dist-packages --exclude=pip --exclude=setuptools --exclude=gi \
        --exclude=cryptography --exclude=OpenSSL --exclude=__pycache__ --exclude='pyopenvdb*' \
        --exclude=pygments --exclude=tests -cf - . | tar -C "$py/dist" -xf -
    # The shared libraries python3.11 and the packages' extensions link, less the C runtime and
    # those the GPU bundle (pack.sh) already carries.
    { find "$py" -name '*.so*'; echo "$py/bin/python3.11"; } | xargs -I{} ldd {} 2>/dev/null |
        awk '$3 ~ /^\// {print $3}' | sort -u |
        grep -vE '/(libc|libm|libgcc_s|libstdc\+\+|ld-linux|libpthread|libdl|librt|libapt-pkg|libdbus-1|libsystemd|libudev|libglib-2.0|liboclvox|libopenvdb|libOpenCL)\.so' |
        while read -r l; do cp -L "$l" "$py/so/"; done
    # OpenVDB's module, which liboclvox loads from its own folder on the first .vdb (so the ldd
    # of pack.sh does not find it), into the bundle's lib/ beside liboclvox.
    if [[ -f $build/liboclvox_vdb.so && -f .gpu/bundle.tar.xz ]]; then
        local bundle
        bundle=$(mktemp -d)
        tar -C "$bundle" -xJf .gpu/bundle.tar.xz
        cp -L "$build/liboclvox_vdb.so" "$bundle/oclvox-gpu/lib/"
        tar -C "$bundle" -cJf .gpu/bundle.tar.xz oclvox-gpu
        rm -rf "$bundle"
    fi
    cp -r "$build/python/oclvox" "$py/"
    cp -r python/tests "$py/tests"
    mkdir -p .gpu
    tar -C "$stage" -cf - py | xz -T2 -6 > .gpu/python.tar.xz
    rm -rf "$stage"
    echo "packed $(du -h .gpu/python.tar.xz | cut -f1) into .gpu/python.tar.xz"
}

# Unpacks .gpu/python.tar.xz into /tmp/oclvox-python and writes py/bin/python3 there, a wrapper
# that runs the bundled interpreter with its libraries and packages (and ours): on PATH it serves
# the shell tests' numpy checks too.
unpack() {
    local dir=/tmp/oclvox-python
    if [[ ! -x $dir/py/bin/python3 ]]; then
        mkdir -p "$dir" && tar -C "$dir" -xJf "$root/.gpu/python.tar.xz"
        cat > "$dir/py/bin/python3" <<WRAP
#!/usr/bin/env bash
export LD_LIBRARY_PATH=$dir/py/so\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}
export PYTHONHOME=$dir/py PYTHONPATH=$dir/py:$dir/py/dist
exec $dir/py/bin/python3.11 "\$@"
WRAP
        chmod +x "$dir/py/bin/python3"
    fi
    echo "$dir/py"
}

run() {
    : "${B:?source .gpu/env.sh first}"
    local py source_dir
    py=$(unpack)
    # env.sh links the samples folder where the build looked for it.
    source_dir=$(sed -n 's/^source_dir=//p' "$(dirname "$B")/paths")
    OCLVOX_CLI=$B/oclvox OCLVOX_MESH_DIR=$(dirname "$B")/meshes \
        OCLVOX_SAMPLE_DIR=$source_dir/samples \
        "$py/bin/python3" -m pytest -q -rs -p no:cacheprovider "$py/tests" "$@"
}

case ${1:-} in
pack) shift; pack "$@" ;;
unpack) unpack ;;
run) shift; run "$@" ;;
*) echo "usage: bash scripts/gpu_python.sh pack [BUILD_DIR] | unpack | run [PYTEST_ARGS...]" >&2; exit 2 ;;
esac
