// What the solid voxelization's files share: solid.cpp chooses the inside test and runs it,
// solid_parity.cpp (crossing parity in brick columns) and solid_winding.cpp (the generalized
// winding number) each compute it on an OpenCL device and as a host reference.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "host_memory.hpp"
#include "opencl_runtime.hpp"
#include "overlap_double.hpp"
#include "solid.hpp"
#include "solid_math.h"
#include "timing.hpp"

namespace oclvox::detail {

// Before anything is allocated for them: the sparse result, which may hold every one of `bricks`
// bricks, plus `working_bytes` of dense working state, against the host memory budget.
inline void check_solid_memory(const SparseVoxels& result, uint64_t bricks, uint64_t working_bytes,
                               const VoxelizeOptions& options, const std::string& working) {
    const uint64_t brick_bytes = result.blocks_per_brick() * sizeof(uint64_t);
    check_host_memory(bricks * brick_bytes + working_bytes, host_budget(options.host_budget_bytes),
                      "the solid result of " + std::to_string(bricks) + " bricks" + working);
}

// Reports bricks done, throwing Cancelled when the callback says stop.
inline void report_progress(const VoxelizeOptions& options, uint64_t done, uint64_t total) {
    if (options.progress && !options.progress(done, total))
        throw Cancelled("solid voxelization cancelled after " + std::to_string(done) + " of " +
                        std::to_string(total) + " bricks");
}

// ---- parity (solid_parity.cpp) ----

// A mesh's triangles for parity, in fixed-point grid units (filled in full right after sizing).
using ParityTriangles = FilledLaterVector<OvParityTriangle>;

// Vertices snapped to fixed-point grid units, or false if a vertex lies too far outside the grid
// for the exact integer arithmetic of solid_math.h.
bool parity_triangles(const Mesh& mesh, const Grid& grid, ParityTriangles& out);

// The solid by crossing parity into `result`, on the device and on the host (bit for bit the
// same); stats get the timings and counts.
void parity_device(Device::Impl& cl, const ParityTriangles& triangles, SparseVoxels& result,
                   const VoxelizeOptions& options, VoxelizeStats& stats);
void parity_reference(const ParityTriangles& triangles, SparseVoxels& result,
                      const VoxelizeOptions& options, VoxelizeStats& stats);

// ---- winding number (solid_winding.cpp) ----

// The mesh's edges after welding bit-identical positions (ids in the order positions first
// appear): per undirected edge (welded vertex ids, low first), in ascending order, how many
// triangles run it low -> high and high -> low. Triangles with a repeated welded vertex enclose
// nothing and are left out.
struct WeldedEdges {
    std::vector<Vec3d> positions;  // per welded id
    std::vector<std::pair<std::pair<uint32_t, uint32_t>, std::array<uint32_t, 2>>> uses;
};

WeldedEdges weld_edges(const Mesh& mesh);

// The uses of the mesh's edges between welded vertices (`welded`: each vertex's welded id, of
// `vertices`), bucketed by their lower end: bucket v holds, sorted, (u << 1 | d) for each use of
// an edge {v, u} with u > v, d being 1 when the triangle runs it from u to v. Triangles with a
// repeated welded vertex enclose nothing and are left out.
struct EdgeUses {
    std::vector<size_t> first;  // bucket v is upper[first[v] .. first[v + 1])
    FilledLaterVector<uint64_t> upper;
};
EdgeUses edge_uses(const Mesh& mesh, const std::vector<uint32_t>& welded, size_t vertices);

// The winding-number solid into `result`: on the device with tree evaluations only where they
// can matter, and as the exact double-precision sum of every triangle at every voxel centre.
void winding_device(Device::Impl& cl, const Mesh& mesh, SparseVoxels& result,
                    const VoxelizeOptions& options, VoxelizeStats& stats);
void winding_reference(const Mesh& mesh, SparseVoxels& result, const VoxelizeOptions& options);

}  // namespace oclvox::detail
