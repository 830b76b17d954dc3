// One writer per output format; write_voxels picks one by extension. Every writer goes through
// write_file_atomically and throws OutputError naming the path on failure. Each adds its phases
// to `progress`, reports as it goes, and calls progress.finish() before its file is renamed into
// place, so that a cancel (Cancelled, from any report) leaves no file.
#pragma once

#include <array>
#include <string>

#include "oclvox/oclvox.hpp"
#include "progress.hpp"
#include "slabs.hpp"

namespace oclvox::detail {

// binvox (Patrick Min): a cubic grid, run-length encoded. See write_binvox.cpp.
// `slab_bytes` bounds the streaming buffer (tests make it small to cross many slab boundaries).
void write_binvox(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress,
                  uint64_t slab_bytes = kSlabBytes);

// Dense formats stream from the bricks a slab at a time (see slabs.hpp).

// NumPy .npy (dense uint8, arr[i, j, k] is voxel (x=i, y=j, z=k)) plus `<path>.json` describing
// where the voxels are in space.
void write_npy(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress,
               uint64_t slab_bytes = kCachedSlabBytes);

// MagicaVoxel .vox: models of at most 256^3 voxels, placed by a scene graph.
void write_vox(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress);

// The exposed faces of the voxel cubes as a quad mesh in world coordinates (.stl: each quad as
// two triangles), made a slab of `slab_layers` voxel layers at a time (0: as many as keep every
// core busy; tests make it small to cross many slab boundaries).
void write_cube_mesh_obj(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, int64_t slab_layers = 0);
void write_cube_mesh_ply(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, int64_t slab_layers = 0);
void write_cube_mesh_stl(const std::string& path, const SparseVoxels& voxels,
                         ProgressPhases& progress, int64_t slab_layers = 0);

// OpenVDB occupancy: a BoolGrid "occupancy", voxel (i,j,k) at index (i,j,k), written without
// OpenVDB's library. See write_vdb.cpp.
void write_vdb(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress);

// Where OpenVDB's index point (0, 0, 0) lies in world units in every .vdb we write: the centre of
// our voxel (0, 0, 0), so the same integer (i, j, k) addresses the same voxel in both.
// Inline: OpenVDB's module (vdb_module.hpp) computes it too, and reaches only exported symbols.
inline std::array<double, 3> vdb_index_origin(const Grid& grid) {
    return {grid.origin[0] + 0.5 * grid.voxel_size, grid.origin[1] + 0.5 * grid.voxel_size,
            grid.origin[2] + 0.5 * grid.voxel_size};
}

}  // namespace oclvox::detail
