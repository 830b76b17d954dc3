// NumPy .npy writer (format version 1.0, numpy.org/neps/nep-0001-npy-format.html) and its JSON
// sidecar.
//
// The array is dense uint8 (0 or 1) of shape (nx, ny, nz) in Fortran order, so numpy's
// arr[i, j, k] is voxel (x=i, y=j, z=k). Fortran order of that shape means x fastest, so the
// file is a sequence of z-layers: it is streamed a z-slab at a time from the bricks, and the
// largest buffer is one slab, never the whole grid.
//
// The .npy format has no place for the grid's position, so `<path>.json` (e.g. out.npy.json)
// records origin, voxel size, dims and axis order. Appending ".json" to the full name, rather
// than replacing ".npy", keeps it from colliding with another output called out.json.
#include <algorithm>
#include <vector>

#include "npy_format.hpp"
#include "writers.hpp"

namespace oclvox::detail {

void write_npy(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress,
               uint64_t slab_bytes) {
    const Grid& grid = voxels.grid();
    check_dense_size(path, grid.voxel_count(), "a .npy");
    const size_t layers = progress.add(1);
    auto write_layers = [&](std::ostream& out) {
        const int64_t nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
        const int64_t layer = nx * ny;
        const int64_t thickness = slab_thickness(uint64_t(layer), nz, slab_bytes);
        std::vector<uint8_t> slab(size_t(layer * thickness));
        for (int64_t z = 0; z < nz; z += thickness) {
            const int64_t depth = std::min(thickness, nz - z);
            std::fill(slab.begin(), slab.end(), uint8_t(0));
            voxels.mark_box({0, 0, z}, {nx, ny, z + depth}, {1, nx, layer}, slab.data());
            out.write(reinterpret_cast<const char*>(slab.data()), std::streamsize(layer * depth));
            progress.report(layers, uint64_t(z + depth), uint64_t(nz));
        }
        progress.finish();
    };
    nlohmann::json sidecar = npy_sidecar(path, grid);
    sidecar["dtype"] = "uint8, 1 = voxel set, 0 = empty";
    sidecar["voxel_box"] =
        "voxel (i,j,k) is the closed box [origin + (i,j,k)*voxel_size, "
        "origin + (i+1,j+1,k+1)*voxel_size]";
    sidecar["voxels_set"] = voxels.count();
    write_npy_with_sidecar(path, "|u1", grid, write_layers, [&] { return sidecar; });
}

}  // namespace oclvox::detail
