// Device::voxelize: the tiled conservative surface voxelization on an OpenCL device.
//
// Phases: prepare and bin triangles on the host; upload them once; then process the active bricks
// in batches that fit the device budget: per batch, upload the (triangle, brick) pairs, their
// work-item offsets and each work item's pair, clear the batch's brick bits, run the voxel kernel
// over all work items, and merge the bits that come back (whole, or only the non-empty blocks:
// block_download.hpp) into the sparse result. A batch the device cannot allocate memory for is
// retried with half as many bricks, down to one (device_batches.hpp).
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>

#include "binning.hpp"
#include "block_download.hpp"
#include "brick_selection.hpp"
#include "device_batches.hpp"
#include "host_memory.hpp"
#include "opencl_runtime.hpp"
#include "prepare.hpp"
#include "solid.hpp"
#include "surface_tests.hpp"
#include "timing.hpp"

namespace oclvox {

namespace {

using detail::Clock;
using detail::FilledLaterVector;
using detail::seconds_since;

// Work items of one batch are numbered with 32-bit offsets.
constexpr uint64_t kMaxItemsPerBatch = uint64_t(1) << 31;

struct Batch {
    size_t first_brick = 0, brick_count = 0;
    FilledLaterVector<cl_uint> pair_triangle, pair_slot, pair_first_item, item_pair;
    std::vector<cl_int> slot_brick;
    uint64_t items = 0;
};

// Gathers bricks [first, ...) into one batch, limited by slots and work items. Bricks are
// independent, so their pairs are counted and then written in parallel; only the cut by work
// items and the prefix sums are serial, one step a brick.
Batch make_batch(const detail::Binning& binning, const detail::PreparedTriangles& prepared,
                 const Grid& grid, int brick_size, size_t first, size_t max_slots) {
    const auto nbx = uint64_t((grid.dims[0] + brick_size - 1) / brick_size);
    const auto nby = uint64_t((grid.dims[1] + brick_size - 1) / brick_size);
    auto brick_of = [&](size_t b) {
        const uint64_t index = binning.bricks[b];
        return std::array<int, 3>{int(index % nbx), int(index / nbx % nby),
                                  int(index / (nbx * nby))};
    };
    const size_t last = std::min(binning.bricks.size(), first + max_slots);
    const uint64_t pair_base = binning.brick_first_pair[first];

    // Phase 1: the work items of every pair of the candidate bricks, and per brick the items and
    // the pairs that have any.
    FilledLaterVector<cl_uint> pair_items(binning.brick_first_pair[last] - pair_base);
    std::vector<uint64_t> brick_items(last - first), brick_pairs(last - first);
    tbb::parallel_for(first, last, [&](size_t b) {
        const std::array<int, 3> brick = brick_of(b);
        uint64_t items = 0, pairs = 0;
        for (uint64_t p = binning.brick_first_pair[b]; p < binning.brick_first_pair[b + 1]; ++p) {
            detail::OvPairWork work;
            const int blocks = detail::ov_pair_work(
                prepared.ranges[binning.pair_triangle[p]], brick[0], brick[1], brick[2], brick_size,
                int(grid.dims[0]), int(grid.dims[1]), int(grid.dims[2]), &work);
            pair_items[p - pair_base] = cl_uint(detail::ov_pair_items(blocks));
            items += pair_items[p - pair_base];
            pairs += blocks > 0;
        }
        brick_items[b - first] = items;
        brick_pairs[b - first] = pairs;
    });

    // Phase 2: as many bricks as fit the batch's work items, and where each one's pairs and items
    // start (the prefix sums, in place).
    Batch batch;
    batch.first_brick = first;
    uint64_t pairs = 0;
    for (size_t b = first; b < last; ++b) {
        const uint64_t items = brick_items[b - first];
        if (batch.items + items > kMaxItemsPerBatch) {
            if (b == first)
                throw GridError("brick " + std::to_string(binning.bricks[b]) + " needs " +
                                std::to_string(items) +
                                " work items, more than one batch can hold: use smaller bricks");
            break;
        }
        brick_items[b - first] = batch.items;
        batch.items += items;
        const uint64_t brick_pair_count = brick_pairs[b - first];
        brick_pairs[b - first] = pairs;
        pairs += brick_pair_count;
        ++batch.brick_count;
    }

    // Phase 3: the batch's pairs and each work item's pair, bricks in parallel.
    batch.pair_triangle.resize(pairs);
    batch.pair_slot.resize(pairs);
    batch.pair_first_item.resize(pairs);
    batch.item_pair.resize(batch.items);
    batch.slot_brick.resize(3 * batch.brick_count);
    tbb::parallel_for(size_t(0), batch.brick_count, [&](size_t slot) {
        const size_t b = first + slot;
        const std::array<int, 3> brick = brick_of(b);
        for (int k = 0; k < 3; ++k) batch.slot_brick[3 * slot + k] = brick[k];
        uint64_t pair = brick_pairs[slot], item = brick_items[slot];
        for (uint64_t p = binning.brick_first_pair[b]; p < binning.brick_first_pair[b + 1]; ++p) {
            const cl_uint n = pair_items[p - pair_base];
            if (n == 0) continue;
            batch.pair_triangle[pair] = binning.pair_triangle[p];
            batch.pair_slot[pair] = cl_uint(slot);
            batch.pair_first_item[pair] = cl_uint(item);
            std::fill_n(batch.item_pair.begin() + ptrdiff_t(item), n, cl_uint(pair));
            ++pair;
            item += n;
        }
    });
    return batch;
}

}  // namespace

SparseVoxels Device::voxelize(const Mesh& mesh, const Grid& grid, const VoxelizeOptions& options,
                              VoxelizeStats* stats_out) {
    SparseVoxels result(grid, options.brick_size);
    const detail::BrickSelection selection(options.bricks, result);
    // Solid and filled: the inside voxels, plus (filled) the conservative surface.
    if (options.mode == VoxelizeMode::Solid || options.mode == VoxelizeMode::Filled) {
        VoxelizeStats stats;
        SparseVoxels out = detail::solid_device(*impl_, mesh, grid, options, stats);
        if (options.mode == VoxelizeMode::Filled) {
            VoxelizeOptions surface_options = options;
            surface_options.mode = VoxelizeMode::Surface;
            VoxelizeStats surface_stats;
            const SparseVoxels surface = voxelize(mesh, grid, surface_options, &surface_stats);
            stats.allocation_retries += surface_stats.allocation_retries;
            detail::finish_solid(out, &surface, selection, stats);
        } else {
            detail::finish_solid(out, nullptr, selection, stats);
        }
        if (stats_out) *stats_out = stats;
        return out;
    }
    VoxelizeStats stats;
    const int brick_size = options.brick_size;
    Impl& cl = *impl_;

    // Phase 1: prepare and bin on the host.
    auto t = Clock::now();
    const detail::PreparedTriangles prepared =
        detail::prepare_triangles(mesh, grid, options.boundary);
    const detail::Binning binning = detail::bin_triangles(prepared, grid, brick_size, selection);
    const auto nbricks = result.brick_dims();
    stats.triangles_in = mesh.triangles.size();
    stats.triangles_used = prepared.triangles.size();
    stats.brick_pairs = binning.pair_triangle.size();
    stats.bricks_total = uint64_t(nbricks[0]) * uint64_t(nbricks[1]) * uint64_t(nbricks[2]);
    stats.bricks_active = binning.bricks.size();
    stats.seconds_binning = seconds_since(t);

    // Phase 2: budgets. The sparse result can need every active brick on the host; the device
    // holds one batch of bricks at a time.
    const uint64_t brick_bytes = result.blocks_per_brick() * sizeof(uint64_t);
    detail::check_host_memory(
        stats.bricks_active * brick_bytes, detail::host_budget(options.host_budget_bytes),
        "the result of " + std::to_string(stats.bricks_active) + " active bricks");
    const uint64_t device_budget =
        detail::batch_budget(cl, options.device_budget_bytes, brick_bytes);
    if (brick_bytes > device_budget)
        throw GridError("one brick of " + std::to_string(brick_size) + "^3 voxels needs " +
                        detail::mib_text(brick_bytes) + ", over the device budget of " +
                        detail::mib_text(device_budget) + ": use smaller bricks");
    const size_t max_slots = size_t(std::max<uint64_t>(1, device_budget / brick_bytes));

    if (!prepared.triangles.empty()) try {
            const cl::Program& program = cl.program(detail::kKernel_voxelize);

            // Phase 3: triangles to the device, once.
            t = Clock::now();
            const cl::Buffer triangles = detail::read_in_place(cl, prepared.triangles);
            cl.queue.finish();
            stats.seconds_upload += seconds_since(t);

            cl::Kernel voxelize(program, detail::surface_kernel(detail::surface_test_for(options)));
            const size_t voxelize_group = detail::work_group_size(voxelize, cl.device);
            const size_t words_per_brick = 2 * result.blocks_per_brick();
            size_t slots = std::min(max_slots, binning.bricks.size());
            detail::SlotBuffer bits(CL_MEM_READ_WRITE, words_per_brick * sizeof(cl_uint));

            // Phase 4: batches of bricks, smaller after a device allocation failure (nothing of
            // a failed batch has been merged).
            auto run_batch = [&](size_t done, size_t max_bricks) {
                t = Clock::now();
                const cl::Buffer& bit_buffer = bits.get(cl.context, max_bricks);
                Batch batch = make_batch(binning, prepared, grid, brick_size, done, max_bricks);
                const size_t bit_words = batch.brick_count * words_per_brick;
                const cl::Buffer pair_triangle = detail::read_in_place(cl, batch.pair_triangle);
                const cl::Buffer pair_slot = detail::read_in_place(cl, batch.pair_slot);
                const cl::Buffer pair_first = detail::read_in_place(cl, batch.pair_first_item);
                const cl::Buffer item_pair = detail::read_in_place(cl, batch.item_pair);
                const cl::Buffer slot_brick = detail::read_in_place(cl, batch.slot_brick);
                cl.queue.enqueueFillBuffer(bit_buffer, cl_uint(0), 0, bit_words * sizeof(cl_uint));
                cl.queue.finish();
                stats.seconds_upload += seconds_since(t);

                t = Clock::now();
                detail::set_args(voxelize, 0, triangles,
                                 cl_int(options.boundary == Boundary::HalfOpen), pair_triangle,
                                 pair_slot, pair_first, item_pair, slot_brick, cl_uint(0),
                                 cl_uint(batch.items), cl_int(brick_size), cl_int(grid.dims[0]),
                                 cl_int(grid.dims[1]), cl_int(grid.dims[2]), bit_buffer);
                detail::run_sliced(cl.queue, batch.items, voxelize_group,
                                   [&](uint64_t first, uint64_t count) {
                                       voxelize.setArg(7, cl_uint(first));
                                       detail::launch(cl.queue, voxelize, count, voxelize_group);
                                   },
                                   {});
                cl.queue.finish();
                stats.seconds_kernels += seconds_since(t);
                stats.work_items += batch.items;

                detail::download_bricks(
                    cl, bit_buffer, batch.brick_count, result.blocks_per_brick(), options.download,
                    stats, [&](size_t slot, const uint64_t* blocks) {
                        result.merge_brick(binning.bricks[batch.first_brick + slot], blocks);
                    });
                ++stats.batches;

                const size_t finished = done + batch.brick_count;
                if (options.progress && !options.progress(finished, binning.bricks.size()))
                    throw Cancelled("voxelization cancelled after " + std::to_string(finished) +
                                    " of " + std::to_string(binning.bricks.size()) + " bricks");
                return batch.brick_count;
            };
            detail::run_batches(cl.queue, binning.bricks.size(), slots, stats,
                                "voxelizing on " + cl.info.name, "brick", run_batch);
        } catch (const cl::Error& e) {
            detail::throw_device_error(e, "voxelizing on " + cl.info.name);
        }

    stats.voxels_set = result.count();
    if (stats_out) *stats_out = stats;
    return result;
}

}  // namespace oclvox
