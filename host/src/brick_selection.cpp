// Brick selections: a sorted set, so membership costs a binary search and no storage scales with
// the grid (a 2^20-voxel axis with 4-voxel bricks has 2^54 bricks).
#include "brick_selection.hpp"

#include <algorithm>

namespace oclvox::detail {

BrickSelection::BrickSelection(const std::vector<uint64_t>& bricks, const SparseVoxels& layout)
    : everything_(bricks.empty()), bricks_(bricks) {
    const auto nb = layout.brick_dims();
    const uint64_t column_count = uint64_t(nb[0]) * uint64_t(nb[1]);
    const uint64_t bricks_total = column_count * uint64_t(nb[2]);
    std::sort(bricks_.begin(), bricks_.end());
    bricks_.erase(std::unique(bricks_.begin(), bricks_.end()), bricks_.end());
    if (!bricks_.empty() && bricks_.back() >= bricks_total)
        throw GridError("brick index " + std::to_string(bricks_.back()) +
                        " is outside the grid, which has " + std::to_string(bricks_total) +
                        " bricks of " + std::to_string(layout.brick_size()) + "^3 voxels");
    columns_.reserve(bricks_.size());
    for (const uint64_t brick : bricks_) columns_.push_back(brick % column_count);
    std::sort(columns_.begin(), columns_.end());
    columns_.erase(std::unique(columns_.begin(), columns_.end()), columns_.end());
}

bool BrickSelection::contains(uint64_t brick) const {
    return everything_ || std::binary_search(bricks_.begin(), bricks_.end(), brick);
}

bool BrickSelection::contains_column(uint64_t column) const {
    return everything_ || std::binary_search(columns_.begin(), columns_.end(), column);
}

void BrickSelection::restrict(SparseVoxels& voxels) const {
    if (everything_) return;
    SparseVoxels kept(voxels.grid(), voxels.brick_size());
    for (const uint64_t brick : bricks_)
        if (const uint64_t* blocks = voxels.brick_blocks(brick)) kept.merge_brick(brick, blocks);
    voxels = std::move(kept);
}

}  // namespace oclvox::detail
