// NumPy .npy writer (format version 1.0, numpy.org/neps/nep-0001-npy-format.html) and its JSON
// sidecar.
//
// The array is dense uint8 (0 or 1) of shape (nx, ny, nz) in Fortran order, so numpy's
// arr[i, j, k] is voxel (x=i, y=j, z=k). Fortran order of that shape means x fastest, which is
// exactly SparseVoxels::to_dense's layout: the data is written without reordering.
//
// The .npy format has no place for the grid's position, so `<path>.json` (e.g. out.npy.json)
// records origin, voxel size, dims and axis order. Appending ".json" to the full name, rather
// than replacing ".npy", keeps it from colliding with another output called out.json.
#include <cstdio>
#include <nlohmann/json.hpp>
#include <vector>

#include "atomic_file.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// Magic, version 1.0 and the little-endian header length, then the header dict padded with
// spaces and ended by '\n' so that the data starts at a multiple of 64 bytes (what numpy itself
// writes, and what memory-mapping readers expect).
void write_npy_header(std::ostream& out, const std::array<int64_t, 3>& dims) {
    const std::string dict = "{'descr': '|u1', 'fortran_order': True, 'shape': (" +
                             std::to_string(dims[0]) + ", " + std::to_string(dims[1]) + ", " +
                             std::to_string(dims[2]) + "), }";
    const size_t preamble = 6 + 2 + 2;  // magic, version, header length
    const size_t unpadded = preamble + dict.size() + 1;
    const std::string header = dict + std::string((64 - unpadded % 64) % 64, ' ') + '\n';

    out.write("\x93NUMPY", 6);
    out.put(char(1));
    out.put(char(0));
    write_le_u16(out, uint16_t(header.size()));
    out << header;
}

nlohmann::json sidecar_for(const std::string& npy_path, const SparseVoxels& voxels) {
    const Grid& grid = voxels.grid();
    const size_t slash = npy_path.find_last_of('/');
    return {
        {"file", slash == std::string::npos ? npy_path : npy_path.substr(slash + 1)},
        {"dtype", "uint8, 1 = voxel set, 0 = empty"},
        {"dims", grid.dims},
        {"origin", grid.origin},
        {"voxel_size", grid.voxel_size},
        {"axis_order",
         "arr[i, j, k] is voxel (x=i, y=j, z=k); stored in Fortran order (x fastest)"},
        {"voxel_box",
         "voxel (i,j,k) is the closed box [origin + (i,j,k)*voxel_size, "
         "origin + (i+1,j+1,k+1)*voxel_size]"},
        {"voxels_set", voxels.count()},
    };
}

}  // namespace

void write_npy(const std::string& path, const SparseVoxels& voxels) {
    // Phase 1: the array. to_dense refuses grids too large to hold; that surfaces as OutputError.
    write_file_atomically(path, [&](std::ostream& out) {
        const std::vector<uint8_t> dense = voxels.to_dense();
        write_npy_header(out, voxels.grid().dims);
        out.write(reinterpret_cast<const char*>(dense.data()), std::streamsize(dense.size()));
    });

    // Phase 2: the sidecar. An array without its placement is misleading, so if the sidecar
    // cannot be written the array goes too and nothing is left under either name.
    try {
        const std::string sidecar = sidecar_for(path, voxels).dump(2) + "\n";
        write_file_atomically(path + ".json", [&](std::ostream& out) { out << sidecar; });
    } catch (...) {
        std::remove(path.c_str());
        throw;
    }
}

}  // namespace oclvox::detail
