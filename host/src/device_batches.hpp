// Device work in batches that shrink when the device runs out of memory: the one mechanism behind
// the surface voxelizer's brick batches, the parity solid's brick-column batches and the winding
// number's point batches; and the pairs and work items of the first two's batches. A batch whose
// allocation fails is retried with half as many units, down to one, and each retry is counted in
// VoxelizeStats::allocation_retries.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "host_memory.hpp"
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
inline void check_injected_allocation_fault(size_t bytes) {
    const char* const limit_mib = std::getenv("OCLVOX_FAULT_DEVICE_ALLOCATION_MIB");
    if (limit_mib && double(bytes) > std::strtod(limit_mib, nullptr) * double(1 << 20))
        throw cl::Error(CL_MEM_OBJECT_ALLOCATION_FAILURE, "clCreateBuffer (injected fault)");
}

inline cl::Buffer batch_buffer(const cl::Context& context, cl_mem_flags flags, size_t bytes) {
    check_injected_allocation_fault(bytes);
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

// Bits of a batch, bytes_per_slot bytes per unit, whose first `used` units are zero bytes
// whenever get returns them: the bits work items OR into, and the bits that come back as the
// result. On a device working in the host's memory they lie in host pages the device writes in
// place, zeroed on every core, where the device's fill runs on one thread (through PoCL the fill
// took 12 ms of motorBike's 17 MiB at 1024^3, most of it faulting in fresh pages; zeroed on two
// cores, 5 ms). Fresh pages are zero already: bits the kernels write sparsely are left to fault
// in where written (most pages of a surface's bricks never are), as are bits written once (the
// parity solid's blocks, written only where they hold voxels: zeroing them first took 17 ms at
// 1024^3, their faults in the kernel 8 ms; and a brick whose pages were never touched is known
// empty without a read, SparseVoxelsAccess::adopt_bricks), while bits the kernels flip at random
// and then read whole (the parity solid's flips) are zeroed on every core first, as faults inside
// those kernels cost far more (parity solid of bunny00 at 1024^3: voxelize phase 145 ms with the
// flips' pages zeroed first, 173-191 ms without, 2026-11-27). A result can take the pages instead
// of a copy (take_pages, download_bricks), and the next batch gets fresh ones. Elsewhere the bits
// are a device buffer, kept while the batch size stays, that the device fills.
class BitSlotBuffer {
  public:
    enum class FreshPages { FaultWhereWritten, ZeroOnEveryCore };
    BitSlotBuffer(size_t bytes_per_slot, FreshPages fresh_pages)
        : bytes_per_slot_(bytes_per_slot), fresh_pages_(fresh_pages) {}
    const cl::Buffer& get(const Device::Impl& cl, size_t slots, size_t used);

    // The host pages behind the buffer, or nullptr if it is the device's own memory.
    const uint64_t* pages() const { return pages_.get(); }
    // Hands over the pages, dropping the buffer (its work must be finished).
    std::shared_ptr<uint64_t> take_pages() {
        buffer_ = cl::Buffer();
        slots_ = 0;
        return std::move(pages_);
    }

  private:
    size_t bytes_per_slot_;
    FreshPages fresh_pages_;
    size_t slots_ = 0;
    std::shared_ptr<uint64_t> pages_;  // declared before buffer_: released after it
    cl::Buffer buffer_;
};

// Work items of one batch are numbered with 32-bit offsets.
constexpr uint64_t kMaxItemsPerBatch = uint64_t(1) << 31;

// What a unit counter returns for a pair whose whole work is set without a kernel's tests:
// kDirectPair | a direct entry for its unit, whose low bits are a bit's index among the unit's bits
// and whose high bits (below kDirectPair) the kernel that sets it defines (for the surface
// kernels, ov_direct_row: a row of voxels from that bit, the index in the low OV_ROW_FIRST_BITS =
// 48 bits). The batch adds the unit's slot * unit_bits to the entry, which stays within those low
// bits: a batch has far fewer than 2^48 bits (32 TiB).
constexpr uint64_t kDirectPair = uint64_t(1) << 63;

// One batch of a binning's units (bricks, brick columns) for a kernel with a work item per piece
// of a (triangle, unit) pair: units [first_unit, first_unit + unit_count), the pairs that have
// work (their triangle, their unit's slot in the batch, their first work item) and each work
// item's pair; and the direct pairs' entries, their bits now indices among the batch's bits (slot *
// unit_bits + the bit's index in its unit).
struct PairBatch {
    size_t first_unit = 0, unit_count = 0;
    FilledLaterVector<cl_uint> pair_triangle, pair_slot, pair_first_item, item_pair;
    FilledLaterVector<cl_ulong> direct_entries;
    uint64_t items = 0;
};

// Gathers units [first, ...) of a binning (unit u's triangles are
// pair_triangle[first_pair[u] .. first_pair[u + 1]), its name units[u]) into one batch of at
// most max_slots units and max_items work items. unit_counter(u) gives a function of a triangle
// that returns its work items in unit u (0: none, fewer than 2^32), or kDirectPair | a direct
// entry in the unit (unit_bits bits a unit) that is the pair's whole work. Units are independent,
// so their pairs are counted and then written in parallel; only the cut and the prefix sums are
// serial, a step a unit. Throws GridError, naming `unit_name`, if one unit alone has too many work
// items.
template <class UnitCounter>
PairBatch make_pair_batch(const std::vector<uint64_t>& units,
                          const std::vector<uint64_t>& first_pair,
                          const std::vector<uint32_t>& pair_triangle, size_t first,
                          size_t max_slots, const char* unit_name, uint64_t unit_bits,
                          UnitCounter&& unit_counter, uint64_t max_items = kMaxItemsPerBatch) {
    const size_t last = std::min(units.size(), first + max_slots);
    const uint64_t pair_base = first_pair[first];

    // Phase 1: the work of every pair of the candidate units, and per unit its items, the pairs
    // that have any and its direct pairs.
    struct UnitCounts {
        uint64_t items, pairs, directs;
    };
    FilledLaterVector<uint64_t> pair_work(first_pair[last] - pair_base);
    std::vector<UnitCounts> unit(last - first);
    tbb::parallel_for(first, last, [&](size_t u) {
        const auto work_of = unit_counter(u);
        UnitCounts counts{0, 0, 0};
        for (uint64_t p = first_pair[u]; p < first_pair[u + 1]; ++p) {
            const uint64_t n = work_of(pair_triangle[p]);
            pair_work[p - pair_base] = n;
            if (n & kDirectPair) {
                ++counts.directs;
            } else {
                counts.items += n;
                counts.pairs += n > 0;
            }
        }
        unit[u - first] = counts;
    });

    // Phase 2: as many units as fit the batch's work items, and where each one's pairs, items and
    // direct bits start (prefix sums, in place).
    PairBatch batch;
    batch.first_unit = first;
    UnitCounts total{0, 0, 0};
    for (size_t u = first; u < last; ++u) {
        const UnitCounts counts = unit[u - first];
        if (total.items + counts.items > max_items) {
            if (u == first)
                throw GridError(std::string(unit_name) + " " + std::to_string(units[u]) +
                                " needs " + std::to_string(counts.items) +
                                " work items, more than one batch can hold: use smaller bricks");
            break;
        }
        unit[u - first] = total;
        total.items += counts.items;
        total.pairs += counts.pairs;
        total.directs += counts.directs;
        ++batch.unit_count;
    }
    batch.items = total.items;

    // Phase 3: the batch's pairs, each work item's pair and the direct bits, units in parallel.
    batch.pair_triangle.resize(total.pairs);
    batch.pair_slot.resize(total.pairs);
    batch.pair_first_item.resize(total.pairs);
    batch.item_pair.resize(total.items);
    batch.direct_entries.resize(total.directs);
    tbb::parallel_for(size_t(0), batch.unit_count, [&](size_t slot) {
        const size_t u = first + slot;
        UnitCounts next = unit[slot];
        for (uint64_t p = first_pair[u]; p < first_pair[u + 1]; ++p) {
            const uint64_t n = pair_work[p - pair_base];
            if (n & kDirectPair) {
                batch.direct_entries[next.directs++] = slot * unit_bits + (n & ~kDirectPair);
                continue;
            }
            if (n == 0) continue;
            batch.pair_triangle[next.pairs] = pair_triangle[p];
            batch.pair_slot[next.pairs] = cl_uint(slot);
            batch.pair_first_item[next.pairs] = cl_uint(next.items);
            std::fill_n(batch.item_pair.begin() + ptrdiff_t(next.items), n, cl_uint(next.pairs));
            ++next.pairs;
            next.items += n;
        }
    });
    return batch;
}

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
