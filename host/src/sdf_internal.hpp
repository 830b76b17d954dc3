// What the distance-field reference (sdf.cpp) and the device path (sdf_device.cpp) share: the
// prepared triangles with their work items, the tree full grids search, the progress phases, the
// squared distances each side computes and the final conversion from them to a field.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "bit_count.hpp"
#include "kernel_sources.hpp"
#include "oclvox/sdf.hpp"
#include "progress.hpp"
#include "sdf_math.h"
#include "timing.hpp"

namespace oclvox::detail {

// The triangles that can come within the band of a grid voxel centre, and their work items: one
// per (triangle, 4x4x4 block aligned to multiples of 4) overlapping the triangle's voxel range,
// numbered triangle by triangle, triangle t owning [first_item[t], first_item[t + 1]).
struct SdfTriangles {
    std::vector<OvSdfTriangle> triangles;
    std::vector<uint64_t> first_item;
    float band = 0, band2 = 0;  // band in voxels and its square, as the kernels compare them
};

// The work items of a prepared triangle: the 4x4x4 blocks (aligned to multiples of 4) its voxel
// range overlaps.
inline uint64_t item_count(const OvSdfTriangle& t) {
    uint64_t blocks = 1;
    for (int k = 0; k < 3; ++k) {
        if (t.lo[k] > t.hi[k]) return 0;  // no voxel within the band (kept for a full grid)
        blocks *= uint64_t(t.hi[k] / 4 - t.lo[k] / 4 + 1);
    }
    return blocks;
}

// The band pass's visit order, shared by the dense and the sparse reference: on_block(bx, by, bz)
// for every 4x4x4 block (minimum voxel, multiples of 4) of t's voxel range that the block cull
// keeps, x fastest, as the kernels' work items number them.
template <class OnBlock>
void for_each_near_block(const OvSdfTriangle& t, float band, OnBlock&& on_block) {
    for (int bz = t.lo[2] / 4 * 4; bz <= t.hi[2]; bz += 4)
        for (int by = t.lo[1] / 4 * 4; by <= t.hi[1]; by += 4)
            for (int bx = t.lo[0] / 4 * 4; bx <= t.hi[0]; bx += 4)
                if (ov_block_near(&t, bx, by, bz, band)) on_block(bx, by, bz);
}

// on_sample(i, j, k, d2) for every voxel of the block and of t's range whose squared distance to
// t is below band2, as the band kernels visit them.
template <class OnSample>
void for_each_band_sample(const OvSdfTriangle& t, int bx, int by, int bz, float band, float band2,
                          OnSample&& on_sample) {
    for (int k = std::max(bz, t.lo[2]); k <= std::min(bz + 3, t.hi[2]); ++k)
        for (int j = std::max(by, t.lo[1]); j <= std::min(by + 3, t.hi[1]); ++j)
            for (int i = std::max(bx, t.lo[0]); i <= std::min(bx + 3, t.hi[0]); ++i) {
                if (!ov_voxel_near(&t, i, j, k, band)) continue;
                const float d2 = ov_voxel_distance2(&t, i, j, k);
                if (d2 < band2) on_sample(i, j, k, d2);
            }
}

// Throws GridError for an invalid grid, a band that is not a finite positive number of voxels,
// or layers outside the grid.
void validate_sdf_options(const Grid& grid, const SdfOptions& options);

// validate_sdf_options, and a GridError for a dense field too large to hold: over 2^32 voxels,
// or host_bytes_per_voxel bytes per voxel (the field and the caller's working copies of it) over
// the host memory budget.
void validate_sdf(const Grid& grid, const SdfOptions& options, uint64_t host_bytes_per_voxel);

// The grid of the field a run produces: the whole grid cut to options' layers.
Grid field_grid(const Grid& grid, const SdfOptions& options);

// Cuts prepared triangles (on the whole grid) to options' layers: their voxel ranges are clipped
// to the layers, those left without a voxel dropped (kept with an empty range for a full grid), and
// (for a dense field, whose grid starts at first_layer: `onto_layers`) every z coordinate moved
// down by first_layer. Anchors are integers, so the anchor-relative float vertices, and every
// distance computed from them, stay the same bits.
void keep_layers(SdfTriangles& prepared, const SdfOptions& options, bool onto_layers);

// Validates mesh and grid, maps the triangles to voxel units, drops those farther than the band
// from every voxel centre (unless `every_triangle`: a full grid's voxels beyond the band may be
// nearest to any triangle; those are kept with an empty voxel range, lo > hi, and no work items)
// and computes each one's distance constants (sdf_prepare.cpp).
SdfTriangles prepare_sdf_triangles(const Mesh& mesh, const Grid& grid, double band_voxels,
                                   bool every_triangle = false);

// The tree over the prepared triangles that full-grid fields search beyond the band
// (sdf_tree.cpp; walked by ov_tree_distance2): its nodes, depth first, and the triangle indices
// its leaves hold, leaf by leaf. Empty for no triangles.
struct SdfTree {
    std::vector<OvSdfNode> nodes;
    std::vector<uint32_t> order;
};
SdfTree build_sdf_tree(const std::vector<OvSdfTriangle>& triangles);

// The progress phases of one distance field, in the order they run: the band pass, for full-grid
// fields the search beyond the band, for signed fields the sign (the solid voxelization); for
// sparse fields the leaves, the sign, then the band.
struct SdfPhases {
    size_t leaves = 0, band = 0, far = 0, sign = 0;
};

// Adds them to `progress`, weighted by their estimated cost (see sdf.cpp).
SdfPhases add_sdf_phases(ProgressPhases& progress, const SdfTriangles& prepared, const Grid& grid,
                         const SdfOptions& options, bool sign, bool sparse);

// The stats of a CSG run of two fields: the second field's counts, timings, batches and retries
// added to the first's (its inside test and inside voxels stay the first's).
void add_second_field_stats(VoxelizeStats& stats, const VoxelizeStats& b);

// One field of a run: its mesh, prepared triangles and progress phases.
struct FieldJob {
    const Mesh& mesh;
    SdfTriangles prepared;
    SdfPhases phases;
};

// Prepares the mesh's triangles (cut to options' layers) and adds the field's phases (a sparse
// field's leaves first); the counts go to stats.
FieldJob plan_field(const Mesh& mesh, const Grid& grid, const SdfOptions& options, bool sign,
                    bool sparse, ProgressPhases& progress, VoxelizeStats& stats);

// The squared distances in voxels of every voxel centre to its nearest prepared triangle, below
// band2 (else band2), for full-grid fields everywhere (beyond the band from the tree); float, as
// the kernels compute them. Reports the band and far phases. The device (sdf_device.cpp: the band
// leaf by leaf, as a sparse field's) and the host reference (sdf.cpp: every triangle's band samples
// scattered) return the same values bit for bit; stats get their timings.
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
// field covers its layers from first_layer on). Returns how many it negated.
uint64_t apply_sign(ScalarField& field, const SparseVoxels& inside, int64_t first_layer);

// The Solid voxelization (with options.inside) that signs a field of options' layers of `grid`,
// on `device` or, when it is null, by voxelize_reference; reported as `phase`. stats add its
// timings, its inside test and voxels_set = the inside voxels.
SparseVoxels sign_voxels(Device* device, const Mesh& mesh, const Grid& grid,
                         const SdfOptions& options, ProgressPhases& progress, size_t phase,
                         VoxelizeStats& stats);

// ---- Sparse fields (sdf_sparse.cpp, sdf_sparse_device.cpp) -----------------------------------
// The leaves of a sparse field: a bit per 8x8x8 leaf of the grid, set for every leaf holding a
// block that a triangle's block cull keeps (so every sample within the band lies in a set leaf),
// and per 32-bit word the number of set bits before it. A set leaf's slot, its place among the
// set leaves in index order, is where its samples go.
struct LeafSet {
    std::array<int64_t, 3> dims{};  // leaves along each axis
    std::vector<uint32_t> bits;
    std::vector<uint32_t> rank;
    uint64_t count = 0;  // set leaves

    uint64_t leaf_of_block(int bx, int by, int bz) const {
        return uint64_t(bx >> 3) +
               uint64_t(dims[0]) * (uint64_t(by >> 3) + uint64_t(dims[1]) * uint64_t(bz >> 3));
    }
    // The lowest voxel of a leaf (leaf_of_block's inverse, to the leaf).
    std::array<int64_t, 3> origin(uint64_t leaf) const {
        return {int64_t(leaf % uint64_t(dims[0])) * SparseField::kLeaf,
                int64_t(leaf / uint64_t(dims[0]) % uint64_t(dims[1])) * SparseField::kLeaf,
                int64_t(leaf / (uint64_t(dims[0]) * uint64_t(dims[1]))) * SparseField::kLeaf};
    }
    uint64_t slot(uint64_t leaf) const {
        const size_t word = size_t(leaf >> 5);
        return rank[word] + uint64_t(popcount64(bits[word] & ((1u << (leaf & 31)) - 1u)));
    }
    // The leaf of a slot below count.
    uint64_t leaf_at(uint64_t slot) const;
    // The first set leaf from `leaf` on (there must be one): slot after slot, the next leaf.
    uint64_t set_from(uint64_t leaf) const {
        while (!(bits[size_t(leaf >> 5)] >> (leaf & 31) & 1)) ++leaf;
        return leaf;
    }
    // Counts the set bits into rank and count, once bits are final.
    void rank_bits();
};

// The leaf set of a grid with none set yet. Throws GridError if its bits and ranks do not fit
// the host memory budget.
LeafSet empty_leaf_set(const Grid& grid, const SdfOptions& options);

// The leaves of a sparse field, and for each set leaf (by slot) the triangles whose block cull
// keeps a block of it: triangles[first[slot] .. first[slot + 1]), ascending. The culls are
// conservative, so every sample within the band of a triangle lies in a leaf that lists it.
// rows[p], beside triangles[p]: the leaf's rows (bits 0-7, by y) and layers (bits 8-15, by z)
// that the triangle's voxel range reaches (leaf_rows).
struct BandLeaves {
    LeafSet leaves;
    std::vector<uint32_t> first;  // one per slot, and the end
    std::vector<uint32_t> triangles;
    std::vector<uint16_t> rows;
};

// The band's leaves of the prepared triangles on `grid` (the field's), binned on the host's cores
// (TBB) in a fixed order, reported to `report` (done, total) when it is not empty. Throws GridError
// if the lists do not fit the host memory budget, or if there are 2^32 or more (leaf, triangle)
// pairs.
BandLeaves band_leaves(const SdfTriangles& prepared, const Grid& grid, const SdfOptions& options,
                       const std::function<void(uint64_t done, uint64_t total)>& report);

// The squared voxel distances of the set leaves' samples (as distance2_device, leaf by leaf, x
// fastest in a leaf, band2 where no triangle is within the band), in batches of consecutive
// slots that fit options.device_budget_bytes and at most kMaxBatchLeaves leaves (so the host holds
// one batch beside the field): on_batch(first_slot, slots, distance2) for each, in slot order.
// Each leaf's samples are the minimum over its listed triangles. stats.batches counts the batches.
constexpr uint64_t kMaxBatchLeaves = 32768;
void leaf_distance2_device(Device& device, const SdfTriangles& prepared, const BandLeaves& band,
                           const SdfOptions& options, ProgressPhases& progress, size_t phase,
                           VoxelizeStats& stats,
                           const std::function<void(uint64_t first_slot, uint64_t slots,
                                                    const float* distance2)>& on_batch);

// The CSG rule sample by sample, into a: union min(a, b), intersection max(a, b), difference
// max(a, -b).
inline void combine_samples(float* a, const float* b, size_t n, CsgOp op) {
    for (size_t v = 0; v < n; ++v) {
        switch (op) {
            case CsgOp::Union:
                a[v] = std::min(a[v], b[v]);
                break;
            case CsgOp::Intersection:
                a[v] = std::max(a[v], b[v]);
                break;
            case CsgOp::Difference:
                a[v] = std::max(a[v], -b[v]);
                break;
        }
    }
}

}  // namespace oclvox::detail
