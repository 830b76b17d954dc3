// Internals shared by the host and device meshing (Surface Nets, Marching Cubes): the method
// switch, input checks, the Marching Cubes case table, and the conversion of the per-sample
// records of kernels/meshing_math.h into a Mesh.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "kernel_sources.hpp"
#include "meshing_math.h"
#include "oclvox/field.hpp"
#include "progress.hpp"

namespace oclvox::detail {

enum class MeshingMethod { SurfaceNets, MarchingCubes };

// Throws GridError if the values do not match the grid or exceed the 32-bit sample indices of
// the meshing code, InputError for a non-finite sample or iso. `who` names the caller.
void validate_field(const ScalarField& field, float iso, const char* who);

// The Marching Cubes case table (OM_MC_ENTRIES entries of OM_MC_ENTRY_BYTES), derived once.
const std::vector<uint8_t>& marching_cubes_table();

// The cubic bricks of `brick_size` samples that can hold surface (those whose samples, with the
// one-sample halo their cells and edges reach into, are not all on one side of iso), and the
// slots of their samples in the count and offset arrays (see OmTiling in meshing_math.h).
struct BrickLayout {
    OmTiling tiling{};
    std::vector<std::array<int, 3>> origins;  // lowest sample of each active brick, x-fastest
    std::vector<uint32_t> base;               // per brick: first slot, or OM_NO_BRICK
    uint32_t slots = 0;                       // samples of the active bricks
};
// Reports progress slab of bricks by slab (see ProgressPhases::reporter).
BrickLayout active_bricks(const ScalarField& field, float iso, int brick_size,
                          const std::function<void(uint64_t done, uint64_t total)>& report = {});

// The progress phases of both meshers: the search for active bricks, the count pass and the emit
// pass.
struct MeshingPhases {
    size_t scan = 0, count = 0, emit = 0;
};
MeshingPhases add_meshing_phases(ProgressPhases& progress);

// The host reference, processing the grid in cubic bricks of `brick_size` samples; the result
// does not depend on brick_size (>= 1).
Mesh mesh_field_reference(const ScalarField& field, float iso, MeshingMethod method, int brick_size,
                          const ProgressCallback& progress = {});

// Throws GridError naming `who` unless the mesher's host buffers fit the default host memory
// budget: two counts per slot of the active bricks, and once the counts are known 40 bytes per
// vertex and 24 per triangle for the records and the mesh made from them (vertices and
// triangles 0 before then). Called before each of them is allocated.
void check_meshing_memory(uint64_t slots, uint64_t vertices, uint64_t triangles, const char* who);

// Replaces the per-slot counts by their exclusive prefix sum in global sample order (x fastest
// over the whole grid, whatever the tiling) and returns the total; throws GridError naming `what`
// when the total does not fit the 32-bit indices (3 per triangle) of the meshing code.
uint32_t exclusive_scan(const ScalarField& field, const BrickLayout& layout,
                        std::vector<uint32_t>& counts, const char* what);

// Throws GridError naming `what` (vertices, triangles) when `total` of them do not fit the 32-bit
// indices (3 per triangle) of the meshing code.
void check_mesh_indices(uint64_t total, const char* what);

// The world position of a vertex record: owner sample `index` plus `local` (3 floats, voxel units
// relative to it). Samples sit at voxel centres, hence the half voxel. Every mesher converts
// through this, so their positions agree bit for bit.
inline std::array<double, 3> vertex_position(const Grid& grid, const std::array<uint64_t, 3>& index,
                                             const float* local) {
    std::array<double, 3> p;
    for (int k = 0; k < 3; ++k)
        p[k] = grid.origin[k] + (double(index[k]) + 0.5 + double(local[k])) * grid.voxel_size;
    return p;
}

// A sparse field that meshes at iso exactly as `field` does (meshing_sparse.cpp): the 8^3 leaves
// holding a corner of a cell with samples on both sides of iso, and elsewhere only each sample's
// side (as inside voxels under a background beyond iso). Throws as validate_field, and GridError
// naming `who` beyond the host memory budget.
SparseField meshing_view(const ScalarField& field, float iso, const char* who);

// World-space mesh from vertex records (owner sample + position relative to it in voxel units)
// and triangles.
Mesh records_to_mesh(const ScalarField& field, const std::vector<uint32_t>& vertex_sample,
                     const std::vector<float>& vertex_local,
                     const std::vector<uint32_t>& triangles);

}  // namespace oclvox::detail
