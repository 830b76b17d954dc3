// Device::voxelize: the tiled conservative surface voxelization on an OpenCL device.
//
// Phases: prepare and bin triangles on the host; hand them to the device once; then process the
// active bricks in batches that fit the device budget: per batch, build the (triangle, brick)
// pairs, their work-item offsets and each work item's pair (make_pair_batch) and hand them over
// (read in place by a device in the host's memory, else uploaded), clear the batch's brick bits,
// run the voxel kernel over all work items, and merge the bits that come back (whole, or only the
// non-empty blocks: block_download.hpp) into the sparse result. A batch the device cannot allocate
// memory for is retried with half as many bricks, down to one (device_batches.hpp).
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
using detail::seconds_since;

// The grid coordinates of active brick b.
std::array<int, 3> brick_coordinates(const detail::Binning& binning, const Grid& grid,
                                     int brick_size, size_t b) {
    const auto nbx = uint64_t((grid.dims[0] + brick_size - 1) / brick_size);
    const auto nby = uint64_t((grid.dims[1] + brick_size - 1) / brick_size);
    const uint64_t index = binning.bricks[b];
    return {int(index % nbx), int(index / nbx % nby), int(index / (nbx * nby))};
}

// Bricks [first, ...) as one batch: a work item per run of up to OV_BLOCKS_PER_ITEM blocks of a
// triangle's blocks in a brick; for a conservative test (SAT, PEF), a triangle whose range is a
// row of voxels is a direct pair instead, its voxels in the brick one entry (ov_range_is_row).
detail::PairBatch make_batch(const detail::Binning& binning,
                             const detail::PreparedTriangles& prepared, const Grid& grid,
                             int brick_size, bool conservative, size_t first, size_t max_slots) {
    const uint64_t brick_bits = uint64_t(brick_size) * uint64_t(brick_size) * uint64_t(brick_size);
    return detail::make_pair_batch(
        binning.bricks, binning.brick_first_pair, binning.pair_triangle, first, max_slots, "brick",
        brick_bits, [&](size_t b) {
            const std::array<int, 3> brick = brick_coordinates(binning, grid, brick_size, b);
            return [&, brick](uint32_t triangle) -> uint64_t {
                const detail::OvRange& range = prepared.ranges[triangle];
                detail::OvPairWork work;
                const int blocks = detail::ov_pair_work(
                    range, brick[0], brick[1], brick[2], brick_size, int(grid.dims[0]),
                    int(grid.dims[1]), int(grid.dims[2]), &work);
                if (conservative && blocks > 0 && detail::ov_range_is_row(range)) {
                    const int* lo = work.voxel_lo;
                    const int* hi = work.voxel_hi;
                    const int axis = hi[1] != lo[1] ? 1 : hi[2] != lo[2] ? 2 : 0;
                    const uint64_t first_bit =
                        64 * uint64_t(detail::ov_brick_block(lo[0] / 4, lo[1] / 4, lo[2] / 4,
                                                             brick[0], brick[1], brick[2],
                                                             brick_size)) +
                        uint64_t(detail::ov_block_bit(lo[0] & 3, lo[1] & 3, lo[2] & 3));
                    return detail::kDirectPair |
                           detail::ov_direct_row(first_bit, axis, hi[axis] - lo[axis] + 1);
                }
                return uint64_t(detail::ov_pair_items(blocks));
            };
        });
}

}  // namespace

void Device::load_kernels(const VoxelizeOptions& options) {
    try {
        if (options.mode != VoxelizeMode::Solid) impl_->program(detail::kKernel_voxelize);
        if (options.mode == VoxelizeMode::Solid || options.mode == VoxelizeMode::Filled)
            impl_->program(detail::kKernel_solid);
        if (detail::downloads_non_empty_blocks(*impl_, options.download))
            impl_->program(detail::kKernel_blocks);
    } catch (const cl::Error& e) {
        detail::throw_device_error(e, "loading kernels on " + impl_->info.name);
    }
}

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

            const detail::SurfaceTest test = detail::surface_test_for(options);
            cl::Kernel voxelize(program, detail::surface_kernel(test));
            const size_t voxelize_group = detail::work_group_size(voxelize, cl.device);
            cl::Kernel set_direct(program, "set_direct_bits");
            const size_t set_direct_group = detail::work_group_size(set_direct, cl.device);
            const size_t words_per_brick = 2 * result.blocks_per_brick();
            size_t slots = std::min(max_slots, binning.bricks.size());
            detail::BitSlotBuffer bits(words_per_brick * sizeof(cl_uint),
                                       detail::BitSlotBuffer::FreshPages::FaultWhereWritten);

            // Phase 4: batches of bricks, smaller after a device allocation failure (nothing of
            // a failed batch has been merged).
            auto run_batch = [&](size_t done, size_t max_bricks) {
                t = Clock::now();
                const detail::PairBatch batch =
                    make_batch(binning, prepared, grid, brick_size,
                               test != detail::SurfaceTest::Thin, done, max_bricks);
                const cl::Buffer& bit_buffer = bits.get(cl, max_bricks, batch.unit_count);
                std::vector<cl_int> slot_coordinates;  // each slot's brick
                for (size_t slot = 0; slot < batch.unit_count; ++slot)
                    for (const int k : brick_coordinates(binning, grid, brick_size, done + slot))
                        slot_coordinates.push_back(k);
                const cl::Buffer pair_triangle = detail::read_in_place(cl, batch.pair_triangle);
                const cl::Buffer pair_slot = detail::read_in_place(cl, batch.pair_slot);
                const cl::Buffer pair_first = detail::read_in_place(cl, batch.pair_first_item);
                const cl::Buffer item_pair = detail::read_in_place(cl, batch.item_pair);
                const cl::Buffer slot_brick = detail::read_in_place(cl, slot_coordinates);
                const cl::Buffer direct_rows = detail::read_in_place(cl, batch.direct_entries);
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
                const uint64_t directs = batch.direct_entries.size();
                detail::set_args(set_direct, 0, direct_rows, cl_uint(0), cl_uint(directs),
                                 cl_int(brick_size), bit_buffer);
                detail::run_sliced(cl.queue, directs, set_direct_group,
                                   [&](uint64_t first, uint64_t count) {
                                       set_direct.setArg(1, cl_uint(first));
                                       detail::launch(cl.queue, set_direct, count,
                                                      set_direct_group);
                                   },
                                   {});
                cl.queue.finish();
                stats.seconds_kernels += seconds_since(t);
                stats.work_items += batch.items + directs;

                detail::download_bricks(
                    cl, bit_buffer, bits, batch.unit_count, result.blocks_per_brick(),
                    options.download, stats,
                    [&](size_t slot) { return binning.bricks[batch.first_unit + slot]; }, result);
                ++stats.batches;

                const size_t finished = done + batch.unit_count;
                if (options.progress && !options.progress(finished, binning.bricks.size()))
                    throw Cancelled("voxelization cancelled after " + std::to_string(finished) +
                                    " of " + std::to_string(binning.bricks.size()) + " bricks");
                return batch.unit_count;
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
