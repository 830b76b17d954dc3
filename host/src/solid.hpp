// Solid voxelization: voxels whose centre is inside the mesh, by crossing parity or by the
// generalized winding number, on an OpenCL device and as a host reference.
#pragma once

#include <functional>
#include <string>

#include "brick_selection.hpp"
#include "kernel_sources.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// Edges of the mesh after welding bit-identical positions, by how they fail to be closed.
// Triangles with a repeated (welded) vertex are ignored.
struct MeshEdgeReport {
    uint64_t edges = 0;
    uint64_t boundary = 0;      // used by one triangle
    uint64_t non_manifold = 0;  // used by more than two
    uint64_t misoriented = 0;   // used by two triangles running it the same way
    // Every edge used by exactly two triangles, whichever way they run it.
    bool closed() const { return boundary == 0 && non_manifold == 0; }
};
MeshEdgeReport mesh_edge_report(const Mesh& mesh);

// The inside test a Solid or Filled run of the whole mesh uses: `requested`, or for Auto the
// choice described below. Throws GridError where that run would (parity forced but impossible).
InsideTest whole_mesh_inside_test(const Mesh& mesh, const Grid& grid, InsideTest requested);

// Calls f(t, column) for every triangle t and brick column (bx + nbx * by of brick_size bricks)
// where t can flip a voxel: the pairs the parity test bins. The mesh must fit exact parity
// arithmetic (whole_mesh_inside_test chose Parity).
void for_each_parity_column(const Mesh& mesh, const Grid& grid, int brick_size,
                            const std::function<void(uint32_t, uint64_t)>& f);

// Both return the solid voxels only (no surface), in options.brick_size bricks, and set
// stats.inside_test and stats.inside_test_reason. Auto picks parity for a closed mesh (every
// edge shared by exactly two triangles, whichever way they run it: parity does not depend on
// orientation) that fits the exact parity arithmetic, and the winding number otherwise. Solid works
// from the mesh itself, not the surface's prepared triangles: it needs every triangle, unclipped
// and including those outside the grid.
SparseVoxels solid_device(Device::Impl& cl, const Mesh& mesh, const Grid& grid,
                          const VoxelizeOptions& options, VoxelizeStats& stats);
SparseVoxels solid_reference(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                             VoxelizeStats& stats);

// The end of a solid or filled voxelization whose stats count the solid's voxels: ORs in the
// conservative surface (Filled; `surface` is null otherwise), drops the bricks `selection` does
// not hold, and counts the voxels again only if either step could change them (counting a large
// solid is not free).
inline void finish_solid(SparseVoxels& solid, const SparseVoxels* surface,
                         const BrickSelection& selection, VoxelizeStats& stats) {
    if (surface)
        for (const uint64_t index : surface->brick_indices())
            solid.merge_brick(index, surface->brick_blocks(index));
    selection.restrict(solid);
    if (surface || !selection.everything()) stats.voxels_set = solid.count();
}

}  // namespace oclvox::detail
