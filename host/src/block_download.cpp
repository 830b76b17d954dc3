// Downloads of brick bits: whole batches read in place, or only the non-empty 4^3 blocks,
// compacted on the device (kernels/blocks.cl). Most blocks of a surface's bricks are empty: at
// 1024^3 and 64^3 bricks, a surface brick holds a few hundred non-empty blocks of 4096.
#include "block_download.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <vector>

#include "device_batches.hpp"
#include "sparse_voxels_access.hpp"
#include "timing.hpp"

namespace oclvox::detail {

constexpr size_t kGroupBlocks = 64;  // OV_GROUP_BLOCKS of blocks.cl

bool place_compact_blocks(const std::vector<cl_uint>& indices, const std::vector<cl_uint>& words,
                          size_t units, size_t blocks_per_unit, uint64_t* blocks) {
    // A unit's blocks are those whose indices fall in its range, found by binary search; every
    // index is checked against its unit's range and its predecessor before its block is written.
    auto unit_start = [&](uint64_t unit) {
        return size_t(
            std::lower_bound(indices.begin(), indices.end(), unit * blocks_per_unit,
                             [](cl_uint index, uint64_t block) { return index < block; }) -
            indices.begin());
    };
    std::atomic<bool> valid{unit_start(units) == indices.size()};  // none beyond the batch
    tbb::parallel_for(size_t(0), units, [&](size_t u) {
        const size_t begin = unit_start(u), end = unit_start(u + 1);
        if (end < begin) valid = false;  // the indices do not ascend
        const uint64_t first_block = uint64_t(u) * blocks_per_unit;
        for (size_t i = begin; i < end; ++i) {
            const uint64_t block = indices[i];
            if (block < first_block || block >= first_block + blocks_per_unit ||
                (i > begin && block <= indices[i - 1])) {
                valid = false;
                return;
            }
            blocks[block] = uint64_t(words[2 * i]) | uint64_t(words[2 * i + 1]) << 32;
        }
    });
    return valid;
}

void download_bricks(Device::Impl& cl, const cl::Buffer& bits, BitSlotBuffer& bit_slots,
                     size_t units, size_t blocks_per_unit, Download mode, VoxelizeStats& stats,
                     const std::function<uint64_t(size_t unit)>& brick_of, SparseVoxels& result) {
    const auto start = Clock::now();
    const uint64_t block_count = uint64_t(units) * blocks_per_unit;
    // Block indices are 32-bit on the device.
    const bool compact = block_count < (uint64_t(1) << 32) && downloads_non_empty_blocks(cl, mode);
    if (!compact) {
        // Mapped, the bits are up to date in the host's memory: where they already lie in the
        // pages behind the buffer (a device in the host's memory), the result takes the pages.
        constexpr bool kLittleEndian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;
        bool in_place = false;
        read_mapped<cl_uint>(cl.queue, bits, 2 * block_count, [&](const cl_uint* words) {
            in_place = kLittleEndian && bit_slots.pages() &&
                       static_cast<const void*>(words) == bit_slots.pages();
            if (in_place) return;
            result.merge_bricks(units, brick_of, [&](size_t unit, uint64_t* blocks) {
                const cl_uint* unit_words = words + 2 * unit * blocks_per_unit;
                for (size_t b = 0; b < blocks_per_unit; ++b)
                    blocks[b] = uint64_t(unit_words[2 * b]) | uint64_t(unit_words[2 * b + 1]) << 32;
            });
        });
        if (in_place) {
            cl.queue.finish();  // the unmap
            SparseVoxelsAccess::adopt_bricks(result, bit_slots.take_pages(), units, brick_of);
        }
        stats.bytes_downloaded += 2 * block_count * sizeof(cl_uint);
        stats.seconds_download += seconds_since(start);
        return;
    }

    // Phase 1: the non-empty blocks of each group of 64, counted on the device.
    const cl::Program& program = cl.program(kKernel_blocks);
    cl::Kernel count_kernel(program, "block_counts"), compact_kernel(program, "compact_blocks");
    const uint64_t groups = (block_count + kGroupBlocks - 1) / kGroupBlocks;
    const cl::Buffer counts = batch_buffer(cl.context, CL_MEM_READ_WRITE, groups * sizeof(cl_uint));
    auto run_groups = [&](cl::Kernel& kernel) {
        run_sliced(cl.queue, groups * kGroupBlocks, kGroupBlocks,
                   [&](uint64_t first, uint64_t count) {
                       kernel.setArg(2, cl_uint(first));
                       launch(cl.queue, kernel, count, kGroupBlocks);
                   },
                   {});
    };
    set_args(count_kernel, 0, bits, cl_uint(block_count), cl_uint(0), counts);
    run_groups(count_kernel);

    // Phase 2: each group's first place in the compact list, on the host.
    std::vector<cl_uint> offsets(groups);
    cl.queue.enqueueReadBuffer(counts, CL_TRUE, 0, groups * sizeof(cl_uint), offsets.data());
    stats.bytes_downloaded += groups * sizeof(cl_uint);
    uint64_t total = 0;
    for (cl_uint& offset : offsets) {
        const uint64_t count = offset;
        offset = cl_uint(total);
        total += count;
    }
    if (total == 0) {
        stats.seconds_download += seconds_since(start);
        return;
    }

    // Phase 3: the non-empty blocks, in block order, compacted on the device and read back.
    const cl::Buffer offset_buffer = upload(cl.context, cl.queue, offsets);
    const cl::Buffer indices = batch_buffer(cl.context, CL_MEM_READ_WRITE, total * sizeof(cl_uint));
    const cl::Buffer words =
        batch_buffer(cl.context, CL_MEM_READ_WRITE, 2 * total * sizeof(cl_uint));
    set_args(compact_kernel, 0, bits, cl_uint(block_count), cl_uint(0), offset_buffer, indices,
             words);
    run_groups(compact_kernel);
    std::vector<cl_uint> index_back(total), words_back(2 * total);
    cl.queue.enqueueReadBuffer(indices, CL_FALSE, 0, total * sizeof(cl_uint), index_back.data());
    cl.queue.enqueueReadBuffer(words, CL_TRUE, 0, 2 * total * sizeof(cl_uint), words_back.data());
    stats.bytes_downloaded += 3 * total * sizeof(cl_uint);

    // Phase 4: each unit's blocks written into fresh pages, which the result then takes as its
    // bricks where they lie (adopt_bricks: a unit without blocks leaves its pages untouched and is
    // no brick). Merged brick by brick instead, every brick was a zeroed allocation of its own,
    // and zeroing was most of the host's part of the download.
    const std::shared_ptr<uint64_t> run = zeroed_host_pages(block_count * sizeof(uint64_t));
    if (!run)  // a smaller batch may succeed (run_batches)
        throw cl::Error(CL_OUT_OF_HOST_MEMORY, "mmap of a downloaded batch's bricks");
    if (!place_compact_blocks(index_back, words_back, units, blocks_per_unit, run.get()))
        throw DeviceError("the device's compacted blocks are out of order or range (" +
                          std::to_string(total) + " blocks of a batch of " +
                          std::to_string(block_count) + ")");
    SparseVoxelsAccess::adopt_bricks(result, run, units, brick_of);
    stats.seconds_download += seconds_since(start);
}

}  // namespace oclvox::detail
