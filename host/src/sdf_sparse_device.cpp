// Sparse narrow-band fields on an OpenCL device: band_leaves marks the leaves over the band's work
// items, then band_distance_leaves fills the samples of a batch of leaves at a time, and only
// those samples come back. The same prepared triangles and predicates as the reference in
// sdf_sparse.cpp, so the leaves and samples match it bit for bit.
#include <algorithm>
#include <chrono>
#include <climits>
#include <cstring>

#include "device_batches.hpp"
#include "sdf_internal.hpp"

namespace oclvox::detail {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr size_t kLeafBytes = SparseField::kLeafSamples * sizeof(cl_uint);

// The prepared triangles on the device, and a kernel of the sdf program with the band kernels'
// leading arguments (triangles, item offsets, triangle count, band at 5) set; run() sets the
// items (item_base at 3, item_end at 4).
struct BandItems {
    BandItems(Device::Impl& cl, const SdfTriangles& prepared)
        : cl(cl),
          prepared(prepared),
          first_item(prepared.first_item.begin(), prepared.first_item.end()),
          triangles(upload(cl.context, cl.queue, prepared.triangles)),
          first(upload(cl.context, cl.queue, first_item)) {}

    cl::Kernel kernel(const char* name) const {
        cl::Kernel kernel(cl.program(kKernel_sdf), name);
        kernel.setArg(0, triangles);
        kernel.setArg(1, first);
        kernel.setArg(2, cl_uint(prepared.triangles.size()));
        kernel.setArg(5, prepared.band);
        return kernel;
    }

    // Runs `kernel` over items [first, end) in slices, reporting done / total of them to
    // `report`.
    void run(cl::Kernel& kernel, uint64_t first, uint64_t end,
             const std::function<void(uint64_t, uint64_t)>& report) const {
        const size_t group = work_group_size(kernel, cl.device);
        kernel.setArg(4, cl_ulong(end));
        run_sliced(
            cl.queue, end - first, group,
            [&](uint64_t slice_first, uint64_t count) {
                kernel.setArg(3, cl_ulong(first + slice_first));
                launch(cl.queue, kernel, count, group);
            },
            report);
    }

    Device::Impl& cl;
    const SdfTriangles& prepared;
    // The uploads do not block, so their sources live as long as the buffers.
    const std::vector<cl_ulong> first_item;
    cl::Buffer triangles, first;
};

}  // namespace

LeafSet band_leaves_device(Device& device, const SdfTriangles& prepared, const Grid& grid,
                           const SdfOptions& options, ProgressPhases& progress, size_t phase,
                           VoxelizeStats& stats) {
    Device::Impl& cl = device.impl();
    LeafSet leaves = empty_leaf_set(grid, options);
    if (prepared.triangles.empty()) {
        leaves.rank_bits();
        return leaves;
    }
    try {
        // Phase 1: triangles up, the bits cleared.
        auto t = Clock::now();
        const BandItems items(cl, prepared);
        cl::Buffer bits(cl.context, CL_MEM_READ_WRITE, leaves.bits.size() * sizeof(cl_uint));
        cl.queue.enqueueFillBuffer(bits, cl_uint(0), 0, leaves.bits.size() * sizeof(cl_uint));
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        // Phase 2: every kept block marks its leaf.
        t = Clock::now();
        cl::Kernel mark = items.kernel("band_leaves");
        mark.setArg(6, cl_int(leaves.dims[0]));
        mark.setArg(7, cl_int(leaves.dims[1]));
        mark.setArg(8, bits);
        items.run(mark, 0, prepared.first_item.back(), progress.reporter(phase));
        cl.queue.finish();
        stats.seconds_kernels += seconds_since(t);

        // Phase 3: the bits back, ranked here (a pass over one bit per leaf).
        t = Clock::now();
        cl.queue.enqueueReadBuffer(bits, CL_TRUE, 0, leaves.bits.size() * sizeof(cl_uint),
                                   leaves.bits.data());
        stats.seconds_download += seconds_since(t);
    } catch (const cl::Error& e) {
        throw_device_error(e, "finding the leaves of a distance field on " + cl.info.name);
    }
    leaves.rank_bits();
    return leaves;
}

void leaf_distance2_device(Device& device, const SdfTriangles& prepared, const LeafSet& leaves,
                           const SdfOptions& options, ProgressPhases& progress, size_t phase,
                           VoxelizeStats& stats,
                           const std::function<void(uint64_t first_slot, uint64_t slots,
                                                    const float* distance2)>& on_batch) {
    Device::Impl& cl = device.impl();
    if (leaves.count == 0) return;
    const std::string doing = "computing a sparse distance field on " + cl.info.name;
    try {
        // Phase 1: triangles, leaf bits and ranks up.
        auto t = Clock::now();
        const BandItems items(cl, prepared);
        const cl::Buffer bits = upload(cl.context, cl.queue, leaves.bits);
        const cl::Buffer rank = upload(cl.context, cl.queue, leaves.rank);
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        cl::Kernel band = items.kernel("band_distance_leaves");
        band.setArg(6, prepared.band2);
        band.setArg(7, cl_int(leaves.dims[0]));
        band.setArg(8, cl_int(leaves.dims[1]));
        band.setArg(9, bits);
        band.setArg(10, rank);

        // Phase 2: the triangles that can reach a batch's layers: those after the first whose
        // highest layer so far reaches the batch's lowest, and before the first from which on
        // every lowest layer is above the batch's highest.
        const size_t n = prepared.triangles.size();
        std::vector<int> highest_so_far(n), lowest_from(n);
        for (size_t i = 0; i < n; ++i)
            highest_so_far[i] =
                std::max(i ? highest_so_far[i - 1] : INT32_MIN, prepared.triangles[i].hi[2]);
        for (size_t i = n; i-- > 0;)
            lowest_from[i] =
                std::min(i + 1 < n ? lowest_from[i + 1] : INT32_MAX, prepared.triangles[i].lo[2]);
        const uint64_t per_layer = uint64_t(leaves.dims[0]) * uint64_t(leaves.dims[1]);
        auto item_range = [&](uint64_t first_slot, uint64_t end_slot) {
            const int low = int(leaves.leaf_at(first_slot) / per_layer) * SparseField::kLeaf;
            const int high = int(leaves.leaf_at(end_slot - 1) / per_layer) * SparseField::kLeaf +
                             SparseField::kLeaf - 1;
            const size_t first =
                size_t(std::lower_bound(highest_so_far.begin(), highest_so_far.end(), low) -
                       highest_so_far.begin());
            const size_t end =
                size_t(std::upper_bound(lowest_from.begin(), lowest_from.end(), high) -
                       lowest_from.begin());
            return std::pair(prepared.first_item[first], prepared.first_item[std::max(first, end)]);
        };

        // Phase 3: batches of consecutive slots as the budget allows, each a pass over its
        // triangles' items that writes only its own leaves, its samples then brought back and
        // handed on.
        const uint64_t budget =
            options.device_budget_bytes
                ? options.device_budget_bytes
                : std::min<uint64_t>(cl.info.max_alloc, cl.info.global_memory / 2);
        size_t slots = size_t(
            std::clamp<uint64_t>(budget / kLeafBytes, 1, std::min(leaves.count, kMaxBatchLeaves)));
        SlotBuffer samples(CL_MEM_READ_WRITE, kLeafBytes);
        std::vector<float> host;
        auto run_batch = [&](uint64_t first_slot, size_t max_slots) {
            const uint64_t count = std::min<uint64_t>(max_slots, leaves.count - first_slot);
            t = Clock::now();
            const cl::Buffer& buffer = samples.get(cl.context, max_slots);
            cl_uint band2_bits;
            std::memcpy(&band2_bits, &prepared.band2, sizeof band2_bits);
            cl.queue.enqueueFillBuffer(buffer, band2_bits, 0, size_t(count) * kLeafBytes);
            band.setArg(11, cl_uint(first_slot));
            band.setArg(12, cl_uint(first_slot + count));
            band.setArg(13, buffer);
            std::function<void(uint64_t, uint64_t)> report;
            if (options.progress)
                report = [&](uint64_t done, uint64_t total) {
                    progress.report(phase, first_slot + count * done / std::max<uint64_t>(total, 1),
                                    leaves.count);
                };
            const auto [first_item, end_item] = item_range(first_slot, first_slot + count);
            items.run(band, first_item, end_item, report);
            cl.queue.finish();
            stats.seconds_kernels += seconds_since(t);

            t = Clock::now();
            host.resize(size_t(count) * SparseField::kLeafSamples);
            cl.queue.enqueueReadBuffer(buffer, CL_TRUE, 0, size_t(count) * kLeafBytes, host.data());
            stats.seconds_download += seconds_since(t);
            on_batch(first_slot, count, host.data());
            ++stats.batches;
            progress.report(phase, first_slot + count, leaves.count);
            return size_t(count);
        };
        run_batches(cl.queue, leaves.count, slots, stats, doing, "leaf", run_batch);
    } catch (const cl::Error& e) {
        throw_device_error(e, doing);
    }
}

}  // namespace oclvox::detail
