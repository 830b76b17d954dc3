// What the distance-field reference (sdf.cpp) and the device path (sdf_device.cpp) share: the
// prepared triangles with their work items, the jump-flooding schedule and the final conversion
// from squared voxel distances to a field.
#pragma once

#include <cstdint>
#include <vector>

#include "kernel_sources.hpp"
#include "oclvox/sdf.hpp"
#include "sdf_math.h"

namespace oclvox::detail {

// "No triangle" in the nearest-triangle buffers.
constexpr uint32_t kNoTriangle = 0xffffffffu;

// The triangles that can come within the band of a grid voxel centre, and their work items: one
// per (triangle, 4x4x4 block aligned to multiples of 4) overlapping the triangle's voxel range,
// numbered triangle by triangle, triangle t owning [first_item[t], first_item[t + 1]).
struct SdfTriangles {
    std::vector<OvSdfTriangle> triangles;
    std::vector<uint64_t> first_item;
    float band = 0, band2 = 0;  // band in voxels and its square, as the kernels compare them
};

// Throws GridError for a band that is not a finite positive number of voxels or a grid whose
// dense field is too large to hold: over 2^32 voxels, or host_bytes_per_voxel bytes per voxel
// (the field and the caller's working copies of it) over the host memory budget.
void validate_sdf(const Grid& grid, const SdfOptions& options, uint64_t host_bytes_per_voxel);

// Validates mesh and grid, maps the triangles to voxel units, drops those farther than the band
// from every voxel centre and computes each one's distance constants (sdf_prepare.cpp).
SdfTriangles prepare_sdf_triangles(const Mesh& mesh, const Grid& grid, double band_voxels);

// Jump-flooding step lengths: powers of two from the largest below the longest grid axis down
// to 1, then 1 again (JFA+1).
std::vector<int> jump_steps(const Grid& grid);

// World-unit field from squared voxel distances (float bits as produced by the kernels):
// narrow band values at or beyond band2 become exactly band * voxel_size.
ScalarField distance_field(const Grid& grid, const SdfOptions& options,
                           const SdfTriangles& prepared, const std::vector<float>& distance2);

// Negates the samples whose voxels are set in `inside`.
void apply_sign(ScalarField& field, const SparseVoxels& inside);

}  // namespace oclvox::detail
