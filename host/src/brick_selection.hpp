// VoxelizeOptions::bricks as the algorithms use it: which bricks (and brick columns) of the whole
// grid a run computes.
#pragma once

#include <cstdint>
#include <vector>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

class BrickSelection {
  public:
    // Every brick if `bricks` is empty. Throws GridError for an index outside the grid's bricks.
    BrickSelection(const std::vector<uint64_t>& bricks, const SparseVoxels& layout);

    bool everything() const { return everything_; }
    bool contains(uint64_t brick) const;
    // Whether any selected brick lies in brick column bx + nbx * by (all heights).
    bool contains_column(uint64_t column) const;

    // Drops from `voxels` every brick that is not selected.
    void restrict(SparseVoxels& voxels) const;

  private:
    bool everything_;
    std::vector<uint64_t> bricks_;   // sorted, unique
    std::vector<uint64_t> columns_;  // sorted, unique
};

}  // namespace oclvox::detail
