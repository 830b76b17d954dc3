// Binning prepared triangles to the bricks of a grid.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "brick_selection.hpp"
#include "prepare.hpp"

namespace oclvox::detail {

// Voxel index / brick size for indices below 2^20 (kMaxGridAxis) and brick sizes up to 1024, as a
// multiply and a shift: ceil(2^40 / size) overestimates 2^40 / size by less than 1, which moves
// x / size by less than x / 2^40 < 2^-20, while a quotient below the next whole number is at
// least 1 / size >= 2^-10 below it; so the floor is exact. Division was most of the per-triangle
// cost of binning (tested exhaustively).
struct BrickDivider {
    explicit BrickDivider(int size)
        : multiplier(((uint64_t(1) << 40) + uint64_t(size) - 1) / uint64_t(size)) {}
    uint32_t operator()(uint32_t index) const { return uint32_t((index * multiplier) >> 40); }
    uint64_t multiplier;
};

// Active bricks (those at least one triangle may touch) in ascending linear index, and for each
// the triangles binned to it: pair_triangle[brick_first_pair[b] .. brick_first_pair[b+1]).
struct Binning {
    std::vector<uint64_t> bricks;
    std::vector<uint64_t> brick_first_pair;
    std::vector<uint32_t> pair_triangle;
};

// Bins into the selected bricks only. Throws GridError if the binning itself would be absurdly
// large (more than max_pairs candidate (triangle, brick) pairs).
Binning bin_triangles(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                      const BrickSelection& selection, uint64_t max_pairs = uint64_t(1) << 31);

// Calls f(t, brick) for every prepared triangle t and brick it may touch: the pairs bin_triangles
// bins without a selection (the same GridError guard).
void for_each_triangle_brick(const PreparedTriangles& prepared, const Grid& grid, int brick_size,
                             const std::function<void(uint32_t, uint64_t)>& f,
                             uint64_t max_pairs = uint64_t(1) << 31);

// The bricks bin_triangles would make active without a selection, sorted, without keeping the
// pairs (the same GridError guard).
std::vector<uint64_t> touched_bricks(const PreparedTriangles& prepared, const Grid& grid,
                                     int brick_size, uint64_t max_pairs = uint64_t(1) << 31);

}  // namespace oclvox::detail
