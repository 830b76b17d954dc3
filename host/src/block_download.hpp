// Voxel results from device memory into the host's sparse result, batch by batch: the one download
// path of the surface and parity batches.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "device_batches.hpp"
#include "opencl_runtime.hpp"

namespace oclvox::detail {

// Whether downloads in `mode` bring back only the non-empty blocks (a batch of 2^32 blocks or
// more comes back whole): Download::Auto does unless the device works in host memory.
inline bool downloads_non_empty_blocks(const Device::Impl& cl, Download mode) {
    return mode == Download::NonEmptyBlocks ||
           (mode == Download::Auto && !cl.info.host_unified_memory);
}

// The blocks of a compact download, `indices` (ascending, among a batch's units x blocks_per_unit
// blocks) and each one's two words (`words`, low first), written to their places in `blocks`
// (units x blocks_per_unit words; the others are left as they are), units in parallel. False
// unless the indices ascend strictly and lie in the batch (a driver has broken them); nothing is
// ever written out of bounds.
bool place_compact_blocks(const std::vector<cl_uint>& indices, const std::vector<cl_uint>& words,
                          size_t units, size_t blocks_per_unit, uint64_t* blocks);

// A batch's `units` bricks in `bits` (each blocks_per_unit 4^3 blocks of two 32-bit words, low
// word first, one brick after another) come back whole or as their non-empty blocks, as `mode`
// says (Download::Auto: non-empty blocks unless the device works in host memory), and are merged
// into `result` as bricks brick_of(unit), in parallel (SparseVoxels::merge_bricks). Where `bits`
// is bit_slots' buffer and its bricks come back whole from the host pages behind it, they are
// not copied: the result takes the pages (on a little-endian host, where two 32-bit words, low
// first, are the block's 64-bit word), and bit_slots gets fresh ones for the next batch; empty
// bricks' pages are given back.
void download_bricks(Device::Impl& cl, const cl::Buffer& bits, BitSlotBuffer& bit_slots,
                     size_t units, size_t blocks_per_unit, Download mode, VoxelizeStats& stats,
                     const std::function<uint64_t(size_t unit)>& brick_of, SparseVoxels& result);

}  // namespace oclvox::detail
