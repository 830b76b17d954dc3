// Bricks taken into a SparseVoxels where they lie, without a copy: how a device batch's results,
// written by the device in the host's memory, become the result.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>

#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

struct SparseVoxelsAccess {
    // Merges `count` bricks as SparseVoxels::merge_bricks would: brick i is brick_index(i), and
    // its words are the i-th blocks_per_brick() words of `run`, memory from zeroed_host_pages. The
    // voxels keep the run and point into it instead of copying. A brick whose pages were never
    // touched (touched_host_pages) is empty and not read; the pages of the other all-zero bricks,
    // and of bricks ORed into one already stored, are given back to the system
    // (release_host_pages).
    static void adopt_bricks(SparseVoxels& voxels, const std::shared_ptr<uint64_t>& run,
                             size_t count, const std::function<uint64_t(size_t)>& brick_index);
};

}  // namespace oclvox::detail
