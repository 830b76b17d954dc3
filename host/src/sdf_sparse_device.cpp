// Sparse narrow-band fields on an OpenCL device: band_leaf_samples fills the samples of a batch of
// leaves at a time, each leaf from the triangles the host binned to it (band_leaves in
// sdf_sparse.cpp), and only those samples come back. The same prepared triangles and predicates as
// the reference in sdf_sparse.cpp, so the samples match it bit for bit.
#include <algorithm>
#include <chrono>

#include "device_batches.hpp"
#include "sdf_internal.hpp"
#include "timing.hpp"

namespace oclvox::detail {

namespace {

constexpr size_t kLeafBytes = SparseField::kLeafSamples * sizeof(cl_uint);
// band_leaf_samples' work group: a leaf's 8x8 columns.
constexpr size_t kLeafGroup = 64;

}  // namespace

void leaf_distance2_device(Device& device, const SdfTriangles& prepared, const BandLeaves& band,
                           const SdfOptions& options, ProgressPhases& progress, size_t phase,
                           VoxelizeStats& stats,
                           const std::function<void(uint64_t first_slot, uint64_t slots,
                                                    const float* distance2)>& on_batch) {
    Device::Impl& cl = device_impl(device);
    const LeafSet& leaves = band.leaves;
    if (leaves.count == 0) return;
    const std::string doing = "computing a sparse distance field on " + cl.info.name;
    try {
        // Phase 1: the triangles, each slot's list and its leaf up (read in place or uploaded
        // without blocking, so their sources live as long as the buffers).
        auto t = Clock::now();
        std::vector<cl_ulong> slot_leaf(size_t(leaves.count));
        for (uint64_t slot = 0, leaf = 0; slot < leaves.count; ++slot, ++leaf)
            slot_leaf[size_t(slot)] = leaf = leaves.set_from(leaf);
        const cl::Buffer triangles = read_in_place(cl, prepared.triangles);
        const cl::Buffer first = read_in_place(cl, band.first);
        const cl::Buffer lists = read_in_place(cl, band.triangles);
        const cl::Buffer rows = read_in_place(cl, band.rows);
        const cl::Buffer leaf_of_slot = read_in_place(cl, slot_leaf);
        cl.queue.finish();
        stats.seconds_upload += seconds_since(t);

        cl::Kernel kernel(cl.program(kKernel_sdf), "band_leaf_samples");
        if (kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(cl.device) < kLeafGroup)
            throw DeviceError(cl.info.name + " cannot run work groups of " +
                              std::to_string(kLeafGroup) +
                              " items, which the sparse distance field needs");
        // Its tile of triangles (band_leaf_samples): more local memory than a device must have
        // (OpenCL's embedded profile promises 1 KB), so said before the launch would fail.
        const cl_ulong local_needed = kernel.getWorkGroupInfo<CL_KERNEL_LOCAL_MEM_SIZE>(cl.device),
                       local_there = cl.device.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>();
        if (local_needed > local_there)
            throw DeviceError(cl.info.name + " has " + std::to_string(local_there) +
                              " bytes of local memory, and the sparse distance field's kernel "
                              "needs " +
                              std::to_string(local_needed));
        set_args(kernel, 0, triangles, first, lists, rows, leaf_of_slot);
        set_args(kernel, 8, cl_int(leaves.dims[0]), cl_int(leaves.dims[1]), prepared.band,
                 prepared.band2);

        // Phase 2: batches of consecutive slots as the budget allows, each leaf a work group that
        // writes only its own samples, which then come back and are handed on.
        const uint64_t budget =
            options.device_budget_bytes
                ? options.device_budget_bytes
                : std::min<uint64_t>(cl.info.max_alloc, cl.info.global_memory / 2);
        size_t slots = size_t(
            std::clamp<uint64_t>(budget / kLeafBytes, 1, std::min(leaves.count, kMaxBatchLeaves)));
        SlotBuffer samples(CL_MEM_WRITE_ONLY, kLeafBytes);
        auto run_batch = [&](uint64_t first_slot, size_t max_slots) {
            const uint64_t count = std::min<uint64_t>(max_slots, leaves.count - first_slot);
            t = Clock::now();
            const cl::Buffer& buffer = samples.get(cl.context, max_slots);
            set_args(kernel, 5, cl_uint(first_slot), cl_uint(0), cl_uint(first_slot + count));
            kernel.setArg(12, buffer);
            std::function<void(uint64_t, uint64_t)> report;
            if (options.progress)
                report = [&](uint64_t done, uint64_t total) {
                    progress.report(phase, first_slot + count * done / std::max<uint64_t>(total, 1),
                                    leaves.count);
                };
            run_sliced(
                cl.queue, count * kLeafGroup, kLeafGroup,
                [&](uint64_t first_item, uint64_t items) {
                    kernel.setArg(6, cl_uint(first_item / kLeafGroup));
                    launch(cl.queue, kernel, items, kLeafGroup);
                },
                report);
            cl.queue.finish();
            stats.seconds_kernels += seconds_since(t);

            t = Clock::now();
            read_mapped<float>(cl.queue, buffer, size_t(count) * SparseField::kLeafSamples,
                               [&](const float* samples) {
                                   stats.seconds_download += seconds_since(t);
                                   on_batch(first_slot, count, samples);
                               });
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
