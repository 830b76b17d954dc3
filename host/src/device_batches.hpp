// Device work in batches that shrink when the device runs out of memory: the one mechanism behind
// the surface voxelizer's brick batches, the parity solid's brick-column batches and the winding
// number's point batches. A batch whose allocation fails is retried with half as many units, down
// to one, and each retry is counted in VoxelizeStats::allocation_retries.
#pragma once

#include <algorithm>
#include <cstdlib>
#include <string>

#include "opencl_runtime.hpp"

namespace oclvox::detail {

// On a device working in the host's memory a batch takes at most this much (unless one unit needs
// more): each batch's buffers are fresh host pages there, which fault in at a few microseconds
// per 4 KiB, and a smaller batch reuses the pages of the one before. Through PoCL on 2 cores,
// parity solid of bunny00 at 1024^3: voxelize phase 0.45 s in one 256 MiB batch, 0.35 s in
// batches of 64 MiB (32 and 16 MiB no better); surface of stanford-bunny at 4096^3: 2.60 s in
// two batches, 2.24 s in seven.
constexpr uint64_t kHostMemoryBatchBytes = uint64_t(64) << 20;

// The device memory one batch may take, given the options' budget: within one allocation and
// half of the device's memory, and on a device in the host's memory within kHostMemoryBatchBytes
// or `unit_bytes` (one unit of the batch), whichever is larger.
inline uint64_t batch_budget(const Device::Impl& cl, uint64_t requested, uint64_t unit_bytes) {
    uint64_t budget = std::min<uint64_t>({requested, cl.info.max_alloc, cl.info.global_memory / 2});
    if (cl.info.host_unified_memory)
        budget = std::min(budget, std::max(kHostMemoryBatchBytes, unit_bytes));
    return budget;
}

// Out-of-memory statuses, after which a smaller batch may succeed.
inline bool is_allocation_failure(cl_int status) {
    return status == CL_MEM_OBJECT_ALLOCATION_FAILURE || status == CL_OUT_OF_RESOURCES ||
           status == CL_OUT_OF_HOST_MEMORY;
}

// A device buffer whose size follows the batch (brick bits, per-point results): what a smaller
// batch makes smaller. Fault injection for tests/fault_test.sh:
// OCLVOX_FAULT_DEVICE_ALLOCATION_MIB=N (a number, fractions allowed) makes every such buffer
// larger than N MiB fail as the device would when out of memory.
inline cl::Buffer batch_buffer(const cl::Context& context, cl_mem_flags flags, size_t bytes) {
    const char* const limit_mib = std::getenv("OCLVOX_FAULT_DEVICE_ALLOCATION_MIB");
    if (limit_mib && double(bytes) > std::strtod(limit_mib, nullptr) * double(1 << 20))
        throw cl::Error(CL_MEM_OBJECT_ALLOCATION_FAILURE, "clCreateBuffer (injected fault)");
    return cl::Buffer(context, flags, bytes);
}

// A batch_buffer of bytes_per_slot bytes per unit of the batch, allocated again only when the
// batch size changes (the old buffer released first, so a shrinking batch never holds both).
class SlotBuffer {
  public:
    SlotBuffer(cl_mem_flags flags, size_t bytes_per_slot)
        : flags_(flags), bytes_per_slot_(bytes_per_slot) {}
    const cl::Buffer& get(const cl::Context& context, size_t slots) {
        if (slots != slots_) {
            buffer_ = cl::Buffer();
            slots_ = 0;
            buffer_ = batch_buffer(context, flags_, slots * bytes_per_slot_);
            slots_ = slots;
        }
        return buffer_;
    }

  private:
    cl_mem_flags flags_;
    size_t bytes_per_slot_;
    cl::Buffer buffer_;
    size_t slots_ = 0;
};

// Runs units [0, total) as batches: run_batch(first, slots) processes units [first, first + k)
// for some k in [1, slots] and returns k. When it fails with a device allocation failure (it must
// not have merged anything of that batch yet), the same units are tried again in batches of half
// as many units, counted in stats.allocation_retries; failing with one unit is a DeviceError
// naming what was being done (`doing`, e.g. "voxelizing on <device>") and the unit. `slots` is the
// largest batch to try, and is left at the size that worked, for later calls.
template <typename RunBatch>
void run_batches(const cl::CommandQueue& queue, uint64_t total, size_t& slots, VoxelizeStats& stats,
                 const std::string& doing, const char* unit, RunBatch&& run_batch) {
    slots = std::max<size_t>(slots, 1);  // a batch of none would never finish
    for (uint64_t done = 0; done < total;) {
        try {
            done += run_batch(done, slots);
        } catch (const cl::Error& e) {
            if (!is_allocation_failure(e.err())) throw;
            if (slots <= 1)
                throw DeviceError("OpenCL error while " + doing + ": " +
                                  (e.what() ? e.what() : "?") + " returned " +
                                  cl_status_name(e.err()) + " even for a batch of one " + unit +
                                  ", after " + std::to_string(stats.allocation_retries) +
                                  " retries with smaller batches");
            slots /= 2;
            ++stats.allocation_retries;
            queue.finish();
        }
    }
}

}  // namespace oclvox::detail
