// Constructive solid geometry on distance fields (min / max / max(a, -b)) and on voxel sets
// (bitwise or / and / and-not, brick by brick), and one grid fitted to two meshes. (CSG of two
// meshes, which computes their fields first, is in sdf.cpp with the other distance-field runs.)
#include <algorithm>
#include <cctype>
#include <cstdint>
#include <iterator>

#include "file_names.hpp"
#include "host_memory.hpp"
#include "oclvox/sdf.hpp"
#include "sdf_internal.hpp"

namespace oclvox {

namespace {

std::string describe(const Grid& g) {
    return std::to_string(g.dims[0]) + "x" + std::to_string(g.dims[1]) + "x" +
           std::to_string(g.dims[2]) + " voxels of " + std::to_string(g.voxel_size) + " at (" +
           std::to_string(g.origin[0]) + ", " + std::to_string(g.origin[1]) + ", " +
           std::to_string(g.origin[2]) + ")";
}

void require_same_grid(const Grid& a, const Grid& b, const char* what) {
    if (!same_grid(a, b))
        throw GridError(std::string("CSG needs both ") + what + " on the same grid, got " +
                        describe(a) + " and " + describe(b) +
                        ": compute both on one grid (fit_grid of both meshes)");
}

// b's voxels re-bricked to `brick_size` (a copy only when the sizes differ).
SparseVoxels with_brick_size(const SparseVoxels& b, int brick_size) {
    if (b.brick_size() == brick_size) return b;
    SparseVoxels out(b.grid(), brick_size);
    b.for_each([&](int64_t i, int64_t j, int64_t k) { out.set(i, j, k); });
    return out;
}

}  // namespace

const char* to_string(CsgOp op) {
    switch (op) {
        case CsgOp::Union:
            return "union";
        case CsgOp::Intersection:
            return "intersection";
        case CsgOp::Difference:
            return "difference";
    }
    return "?";
}

CsgOp csg_op_from_string(const std::string& name) {
    const std::string lower = detail::lowercase(name);
    if (lower == "union") return CsgOp::Union;
    if (lower == "intersection") return CsgOp::Intersection;
    if (lower == "difference") return CsgOp::Difference;
    throw GridError("unknown CSG operation '" + name +
                    "' (expected union, intersection or difference)");
}

ScalarField csg(const ScalarField& a, const ScalarField& b, CsgOp op) {
    require_same_grid(a.grid, b.grid, "fields");
    if (a.values.size() != a.grid.voxel_count() || b.values.size() != b.grid.voxel_count())
        throw GridError("CSG on a field whose value count (" + std::to_string(a.values.size()) +
                        ", " + std::to_string(b.values.size()) + ") does not match its grid's " +
                        std::to_string(a.grid.voxel_count()) + " voxels");
    detail::check_host_memory(
        a.values.size() * sizeof(float), detail::default_host_budget(),
        "the CSG result field of " + std::to_string(a.values.size()) + " samples");
    ScalarField out = a;
    detail::combine_samples(out.values.data(), b.values.data(), out.values.size(), op);
    return out;
}

SparseField csg(const SparseField& a, const SparseField& b, CsgOp op) {
    require_same_grid(a.grid(), b.grid(), "fields");
    if (a.background() != b.background())
        throw GridError("CSG needs both sparse fields with the same band, got " +
                        std::to_string(a.band_voxels()) + " and " +
                        std::to_string(b.band_voxels()) + " voxels");
    // Away from both fields' leaves every sample is +-background, so the result's sign there is
    // the same operation on the inside voxels; the leaves of either field are combined sample by
    // sample, whatever the other field holds there.
    SparseField out(a.grid(), a.band_voxels(), csg(a.inside(), b.inside(), op));
    const std::vector<uint64_t>&ka = a.leaf_indices(), &kb = b.leaf_indices();
    std::vector<uint64_t> leaves;
    std::set_union(ka.begin(), ka.end(), kb.begin(), kb.end(), std::back_inserter(leaves));
    detail::check_host_memory(leaves.size() * SparseField::kLeafSamples * sizeof(float),
                              detail::default_host_budget(),
                              "the CSG result's " + std::to_string(leaves.size()) + " leaves");
    out.reserve_leaves(leaves.size());
    float x[SparseField::kLeafSamples], y[SparseField::kLeafSamples];
    for (const uint64_t leaf : leaves) {
        a.copy_leaf(leaf, x);
        b.copy_leaf(leaf, y);
        detail::combine_samples(x, y, SparseField::kLeafSamples, op);
        out.append_leaf(leaf, x);
    }
    return out;
}

SparseVoxels csg(const SparseVoxels& a, const SparseVoxels& b_in, CsgOp op) {
    require_same_grid(a.grid(), b_in.grid(), "voxel sets");
    const SparseVoxels b = with_brick_size(b_in, a.brick_size());
    SparseVoxels out(a.grid(), a.brick_size());
    const std::vector<uint64_t> empty(a.blocks_per_brick(), 0);
    std::vector<uint64_t> blocks(a.blocks_per_brick());

    // Every brick of the result is a brick of a, or (union only) of b.
    for (const uint64_t index : a.brick_indices()) {
        const uint64_t* a_blocks = a.brick_blocks(index);
        const uint64_t* found = b.brick_blocks(index);
        const uint64_t* b_blocks = found ? found : empty.data();
        for (size_t w = 0; w < blocks.size(); ++w) {
            switch (op) {
                case CsgOp::Union:
                    blocks[w] = a_blocks[w] | b_blocks[w];
                    break;
                case CsgOp::Intersection:
                    blocks[w] = a_blocks[w] & b_blocks[w];
                    break;
                case CsgOp::Difference:
                    blocks[w] = a_blocks[w] & ~b_blocks[w];
                    break;
            }
        }
        out.merge_brick(index, blocks.data());
    }
    if (op == CsgOp::Union)
        for (const uint64_t index : b.brick_indices())
            if (!a.brick_blocks(index)) out.merge_brick(index, b.brick_blocks(index));
    return out;
}

Grid fit_grid(const Mesh& a, const Mesh& b, const GridFit& fit) {
    // The fitted grid depends only on the box of the used vertices, so one mesh holding both
    // (b's indices shifted past a's vertices) has the box of the union.
    validate_mesh(a);
    validate_mesh(b);
    Mesh both;
    both.positions = a.positions;
    both.positions.insert(both.positions.end(), b.positions.begin(), b.positions.end());
    both.triangles = a.triangles;
    if (a.positions.size() + b.positions.size() > uint64_t(UINT32_MAX))
        throw InputError("the two meshes together have more vertices than 32-bit indices reach");
    const auto offset = uint32_t(a.positions.size());
    for (const auto& t : b.triangles)
        both.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
    return fit_grid(both, fit);
}

}  // namespace oclvox
