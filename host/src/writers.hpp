// One writer per output format; write_voxels picks one by extension. Every writer goes through
// write_file_atomically and throws OutputError naming the path on failure.
#pragma once

#include <cstdint>
#include <cstring>
#include <ostream>
#include <string>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// binvox (Patrick Min): a cubic grid, run-length encoded. See write_binvox.cpp.
void write_binvox(const std::string& path, const SparseVoxels& voxels);

// NumPy .npy (dense uint8, arr[i, j, k] is voxel (x=i, y=j, z=k)) plus `<path>.json` describing
// where the voxels are in space.
void write_npy(const std::string& path, const SparseVoxels& voxels);

// MagicaVoxel .vox: models of at most 256^3 voxels, placed by a scene graph.
void write_vox(const std::string& path, const SparseVoxels& voxels);

// The exposed faces of the voxel cubes as a quad mesh in world coordinates.
void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels);
void write_cube_mesh_ply(const std::string& path, const SparseVoxels& voxels);

// Binary formats are little-endian on disk whatever the host's byte order.
inline void write_le(std::ostream& out, uint64_t value, int bytes) {
    char buffer[8];
    for (int b = 0; b < bytes; ++b) buffer[b] = char((value >> (8 * b)) & 0xffu);
    out.write(buffer, bytes);
}
inline void write_le_u16(std::ostream& out, uint16_t value) {
    write_le(out, value, 2);
}
inline void write_le_i32(std::ostream& out, int32_t value) {
    write_le(out, uint32_t(value), 4);
}
inline void write_le_f64(std::ostream& out, double value) {
    uint64_t bits;
    std::memcpy(&bits, &value, sizeof bits);
    write_le(out, bits, 8);
}

}  // namespace oclvox::detail
