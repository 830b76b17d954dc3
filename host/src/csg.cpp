// Constructive solid geometry on distance fields (min / max / max(a, -b)) and on voxel sets
// (bitwise or / and / and-not, brick by brick), and one grid fitted to two meshes. (CSG of two
// meshes, which computes their fields first, is in sdf.cpp with the other distance-field runs.)
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <unordered_map>

#include "file_names.hpp"
#include "host_memory.hpp"
#include "number_text.hpp"
#include "oclvox/sdf.hpp"
#include "sdf_internal.hpp"

namespace oclvox {

namespace {

void require_same_grid(const Grid& a, const Grid& b, const char* what) {
    if (!same_grid(a, b))
        throw GridError(std::string("CSG needs both ") + what + " on the same grid, got " +
                        to_string(a) + " and " + to_string(b) +
                        ": compute both on one grid (fit_grid of both meshes)");
}

// b's voxels re-bricked to `brick_size` (a copy only when the sizes differ).
SparseVoxels with_brick_size(const SparseVoxels& b, int brick_size) {
    if (b.brick_size() == brick_size) return b;
    SparseVoxels out(b.grid(), brick_size);
    b.for_each([&](int64_t i, int64_t j, int64_t k) { out.set(i, j, k); });
    return out;
}

using Index3 = std::array<int64_t, 3>;

// Whether b's voxels lie on a's lattice: the same voxel size and origins a whole number of voxels
// apart (to rounding: files give origins through transforms). `offset` is then the index of b's
// voxel (0, 0, 0) on a's lattice.
bool same_lattice(const Grid& a, const Grid& b, Index3& offset) {
    if (!(std::abs(a.voxel_size - b.voxel_size) <= 1e-9 * a.voxel_size)) return false;
    for (int k = 0; k < 3; ++k) {
        const double voxels = (b.origin[k] - a.origin[k]) / a.voxel_size;
        const double whole = std::round(voxels);
        if (!(std::abs(voxels - whole) <= 1e-6)) return false;
        offset[k] = int64_t(whole);
    }
    return true;
}

// The box of both grids on their lattice (b at `offset` of a): its origin on each axis is that of
// the grid that starts lower, so exact. shift_a, shift_b: where each grid's voxel (0, 0, 0) lands.
Grid covering_grid(const Grid& a, const Grid& b, const Index3& offset, Index3& shift_a,
                   Index3& shift_b) {
    Grid out = a;
    for (int k = 0; k < 3; ++k) {
        const int64_t lo = std::min<int64_t>(0, offset[k]);
        const int64_t hi = std::max(a.dims[k], offset[k] + b.dims[k]);
        out.origin[k] = offset[k] >= 0 ? a.origin[k] : b.origin[k];
        out.dims[k] = hi - lo;
        shift_a[k] = -lo;
        shift_b[k] = offset[k] - lo;
    }
    validate_grid(out);
    return out;
}

// v's voxels on `target`, voxel (i, j, k) moved to (i, j, k) + shift. Shifts by whole 4x4x4 blocks
// move 64-bit words (as the two grids of level sets read from OpenVDB files are, their boxes
// starting on leaves); others move voxel by voxel.
SparseVoxels moved_voxels(const SparseVoxels& v, const Grid& target, const Index3& shift) {
    SparseVoxels out(target, v.brick_size());
    const int64_t block = SparseVoxels::kBlock;
    if (shift[0] % block || shift[1] % block || shift[2] % block) {
        v.for_each([&](int64_t i, int64_t j, int64_t k) {
            out.set(i + shift[0], j + shift[1], k + shift[2]);
        });
        return out;
    }
    const int64_t nb = v.blocks_per_brick_axis();
    const Index3 from = v.brick_dims(), to = out.brick_dims();
    std::unordered_map<uint64_t, std::vector<uint64_t>> bricks;
    for (const uint64_t index : v.brick_indices()) {
        const uint64_t* blocks = v.brick_blocks(index);
        const Index3 brick = {int64_t(index % uint64_t(from[0])),
                              int64_t(index / uint64_t(from[0]) % uint64_t(from[1])),
                              int64_t(index / uint64_t(from[0] * from[1]))};
        for (int64_t b = 0; b < nb * nb * nb; ++b) {
            if (!blocks[b]) continue;
            const Index3 local = {b % nb, b / nb % nb, b / (nb * nb)};
            Index3 at, in;  // the block's brick and place in it, on the target
            for (int k = 0; k < 3; ++k) {
                const int64_t g = brick[k] * nb + local[k] + shift[k] / block;
                at[k] = g / nb;
                in[k] = g % nb;
            }
            std::vector<uint64_t>& words =
                bricks[uint64_t(at[0] + to[0] * (at[1] + to[1] * at[2]))];
            words.resize(v.blocks_per_brick());
            words[size_t(in[0] + nb * (in[1] + nb * in[2]))] |= blocks[b];
        }
    }
    for (const auto& [index, words] : bricks) out.merge_brick(index, words.data());
    return out;
}

// f on `target`, voxel (i, j, k) moved to (i, j, k) + shift, its leaves cut again at the target's
// multiples of 8. Beyond f's grid every sample is +background: a level set's shape lies within
// its grid, as beyond an OpenVDB tree the background is outside.
SparseField moved_field(const SparseField& f, const Grid& target, const Index3& shift) {
    SparseField out(target, f.band_voxels(), moved_voxels(f.inside(), target, shift));
    const int64_t leaf = SparseField::kLeaf;
    const Index3 to = out.leaf_dims();
    const auto& dims = f.grid().dims;

    // Phase 1: the target leaves that f's leaves reach within f's grid (up to 8 each).
    std::vector<uint64_t> keys;
    for (const uint64_t index : f.leaf_indices()) {
        const Index3 o = f.leaf_origin(index);
        Index3 lo, hi;
        for (int k = 0; k < 3; ++k) {
            lo[k] = (o[k] + shift[k]) / leaf;
            hi[k] = (std::min(o[k] + leaf, dims[k]) - 1 + shift[k]) / leaf;
        }
        for (int64_t z = lo[2]; z <= hi[2]; ++z)
            for (int64_t y = lo[1]; y <= hi[1]; ++y)
                for (int64_t x = lo[0]; x <= hi[0]; ++x)
                    keys.push_back(uint64_t(x + to[0] * (y + to[1] * z)));
    }
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    detail::check_host_memory(keys.size() * SparseField::kLeafSamples * sizeof(float),
                              detail::default_host_budget(),
                              "the " + std::to_string(keys.size()) + " leaves of a moved field");

    // Phase 2: each target leaf, from the samples of f's grid it covers.
    out.reserve_leaves(keys.size());
    float samples[SparseField::kLeafSamples], box[SparseField::kLeafSamples];
    for (const uint64_t key : keys) {
        const Index3 o = out.leaf_origin(key);
        Index3 lo, hi;  // the leaf's box in f's voxels, within f's grid
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::max<int64_t>(0, o[k] - shift[k]);
            hi[k] = std::min(dims[k], o[k] - shift[k] + leaf);
        }
        std::fill_n(samples, SparseField::kLeafSamples, f.background());
        f.copy_box(lo, hi, box);
        const int64_t wx = hi[0] - lo[0], wy = hi[1] - lo[1];
        for (int64_t z = lo[2]; z < hi[2]; ++z)
            for (int64_t y = lo[1]; y < hi[1]; ++y)
                std::copy_n(box + wx * ((y - lo[1]) + wy * (z - lo[2])), wx,
                            samples + (lo[0] + shift[0] - o[0]) +
                                leaf * ((y + shift[1] - o[1]) + leaf * (z + shift[2] - o[2])));
        out.append_leaf(key, samples);
    }
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
    if (a.background() != b.background())
        throw GridError("CSG needs both sparse fields with the same band, got " +
                        detail::number_text(a.band_voxels()) + " and " +
                        detail::number_text(b.band_voxels()) + " voxels");
    // Grids on one lattice: both fields moved onto the box of both.
    Index3 offset;
    if (!same_grid(a.grid(), b.grid())) {
        if (!same_lattice(a.grid(), b.grid(), offset))
            throw GridError(
                "CSG needs both fields on one voxel lattice (the same voxel size, "
                "origins a whole number of voxels apart), got " +
                to_string(a.grid()) + " and " + to_string(b.grid()) +
                ": read one level set onto the other's lattice (read_sparse_field with a "
                "lattice and band), or compute both on one grid (fit_grid of both meshes)");
        Index3 shift_a, shift_b;
        const Grid both = covering_grid(a.grid(), b.grid(), offset, shift_a, shift_b);
        return csg(moved_field(a, both, shift_a), moved_field(b, both, shift_b), op);
    }
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
