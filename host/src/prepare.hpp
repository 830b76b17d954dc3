// Turning a Mesh on a Grid into the triangles the kernels and the reference consume.
#pragma once

#include <cstdint>
#include <vector>

#include "host_memory.hpp"
#include "oclvox/oclvox.hpp"
#include "voxel_math.h"

namespace oclvox::detail {

struct PreparedTriangles {
    FilledLaterVector<OvTriangle> triangles;
    FilledLaterVector<OvRange> ranges;  // ov_triangle_range of each triangle
    // The mesh triangle each came from (clipping can split one, or drop it); empty when every
    // mesh triangle prepared into exactly itself.
    FilledLaterVector<uint32_t> source;

    uint32_t source_of(size_t piece) const {
        return source.empty() ? uint32_t(piece) : source[piece];
    }
};

// Validates mesh and grid, maps vertices to grid coordinates (voxel units) in double, drops
// triangles that cannot touch the grid, clips the few that reach far outside it (so huge
// triangles keep their precision and integer ranges stay bounded), and rounds each triangle once
// to float relative to an integer anchor.
// `boundary` decides the voxel ranges (closed or half-open voxel boxes).
PreparedTriangles prepare_triangles(const Mesh& mesh, const Grid& grid,
                                    Boundary boundary = Boundary::Closed);

}  // namespace oclvox::detail
