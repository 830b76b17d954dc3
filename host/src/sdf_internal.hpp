// What the distance-field reference (sdf.cpp) and the device path (sdf_device.cpp) share: the
// prepared triangles with their work items, the jump-flooding schedule, the progress phases, the
// squared distances each side computes and the final conversion from them to a field.
#pragma once

#include <cstdint>
#include <vector>

#include "kernel_sources.hpp"
#include "oclvox/sdf.hpp"
#include "progress.hpp"
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

// Throws GridError for a band that is not a finite positive number of voxels, layers outside the
// grid (or with full_grid), or a field too large to hold: over 2^32 voxels, or
// host_bytes_per_voxel bytes per voxel (the field and the caller's working copies of it) over the
// host memory budget.
void validate_sdf(const Grid& grid, const SdfOptions& options, uint64_t host_bytes_per_voxel);

// The grid of the field a run produces: the whole grid cut to options' layers.
Grid field_grid(const Grid& grid, const SdfOptions& options);

// Cuts prepared triangles (on the whole grid) to options' layers: their voxel ranges are clipped
// to the layers and every z coordinate moved down by first_layer. Anchors are integers, so the
// anchor-relative float vertices, and every distance computed from them, stay the same bits.
void keep_layers(SdfTriangles& prepared, const SdfOptions& options);

// Validates mesh and grid, maps the triangles to voxel units, drops those farther than the band
// from every voxel centre and computes each one's distance constants (sdf_prepare.cpp).
SdfTriangles prepare_sdf_triangles(const Mesh& mesh, const Grid& grid, double band_voxels);

// Jump-flooding step lengths: powers of two from the largest below the longest grid axis down
// to 1, then 1 again (JFA+1).
std::vector<int> jump_steps(const Grid& grid);

// The progress phases of one distance field, in the order they run: the band pass, for full-grid
// fields the nearest-triangle seeds and each jump-flooding pass, for signed fields the sign (the
// solid voxelization).
struct SdfPhases {
    size_t band = 0, seeds = 0, first_jump = 0, sign = 0;
};

// Adds them to `progress`, weighted by their estimated cost (see sdf.cpp).
SdfPhases add_sdf_phases(ProgressPhases& progress, const SdfTriangles& prepared, const Grid& grid,
                         const SdfOptions& options, bool sign);

// The squared distances in voxels of every voxel centre to its nearest prepared triangle, below
// band2 (else band2), for full-grid fields everywhere; float, as the kernels compute them.
// Reports the band, seeds and jump phases. The device (sdf_device.cpp) and the host reference
// (sdf.cpp) return the same values bit for bit; stats get their timings.
std::vector<float> distance2_device(Device& device, const SdfTriangles& prepared, const Grid& grid,
                                    const SdfOptions& options, ProgressPhases& progress,
                                    const SdfPhases& phases, VoxelizeStats& stats);
std::vector<float> distance2_reference(const SdfTriangles& prepared, const Grid& grid,
                                       const SdfOptions& options, ProgressPhases& progress,
                                       const SdfPhases& phases, VoxelizeStats& stats);

// World-unit field from squared voxel distances (float bits as produced by the kernels):
// narrow band values at or beyond band2 become exactly band * voxel_size.
ScalarField distance_field(const Grid& grid, const SdfOptions& options,
                           const SdfTriangles& prepared, const std::vector<float>& distance2);

// Negates the samples whose voxels are set in `inside` (a voxelization of the whole grid; the
// field covers its layers from first_layer on).
void apply_sign(ScalarField& field, const SparseVoxels& inside, int64_t first_layer);

// csg(a, b, op) into a's values (csg.cpp); the grids must already match.
void combine_fields(ScalarField& a, const ScalarField& b, CsgOp op);

}  // namespace oclvox::detail
