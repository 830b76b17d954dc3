// Where a stored brick and its 4^3 blocks sit in the grid (the layout SparseVoxels documents),
// for the writers that walk the bricks directly.
#pragma once

#include <array>
#include <cstdint>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

class BrickLayout {
  public:
    explicit BrickLayout(const SparseVoxels& voxels)
        : nbricks_(voxels.brick_dims()),
          brick_(voxels.brick_size()),
          blocks_(voxels.blocks_per_brick_axis()) {}

    // Bricks per z-layer of bricks: brick index / layer_bricks() is the brick's z.
    uint64_t layer_bricks() const { return uint64_t(nbricks_[0]) * uint64_t(nbricks_[1]); }
    size_t blocks_per_brick() const { return size_t(blocks_ * blocks_ * blocks_); }

    // The voxel at the low corner of brick `index` (bx + nbx*(by + nby*bz)).
    std::array<int64_t, 3> brick_origin(uint64_t index) const {
        return {int64_t(index % uint64_t(nbricks_[0])) * brick_,
                int64_t(index / uint64_t(nbricks_[0]) % uint64_t(nbricks_[1])) * brick_,
                int64_t(index / layer_bricks()) * brick_};
    }
    // The voxel at the low corner of block `word` (x fastest) of brick `index`.
    std::array<int64_t, 3> block_origin(uint64_t index, size_t word) const {
        const auto o = brick_origin(index);
        const int64_t w = int64_t(word);
        return {o[0] + w % blocks_ * SparseVoxels::kBlock,
                o[1] + w / blocks_ % blocks_ * SparseVoxels::kBlock,
                o[2] + w / (blocks_ * blocks_) * SparseVoxels::kBlock};
    }

  private:
    std::array<int64_t, 3> nbricks_;
    int64_t brick_, blocks_;
};

// Bit `bit` of a block word is voxel (bit & 3, bit >> 2 & 3, bit >> 4) of the block.
inline std::array<int64_t, 3> voxel_in_block(int bit) {
    return {bit & 3, bit >> 2 & 3, bit >> 4};
}

}  // namespace oclvox::detail
