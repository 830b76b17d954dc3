// The bit slot buffers of device_batches.hpp.
#include "device_batches.hpp"

#include <cstring>

namespace oclvox::detail {

const cl::Buffer& BitSlotBuffer::get(const Device::Impl& cl, size_t slots, size_t used) {
    const size_t bytes = slots * bytes_per_slot_;
    const size_t used_bytes = std::min(used, slots) * bytes_per_slot_;
    const bool fresh = slots != slots_;
    if (fresh) {  // the old buffer released first, so a shrinking batch never holds both
        take_pages();
        check_injected_allocation_fault(bytes);
        if (!cl.info.host_unified_memory) {
            buffer_ = cl::Buffer(cl.context, CL_MEM_READ_WRITE, bytes);
        } else {
            pages_ = zeroed_host_pages(bytes);
            if (!pages_) throw cl::Error(CL_OUT_OF_HOST_MEMORY, "mmap of the batch's bits");
            buffer_ = cl::Buffer(cl.context, CL_MEM_READ_WRITE | CL_MEM_USE_HOST_PTR, bytes,
                                 pages_.get());
        }
        slots_ = slots;
    }
    if (used_bytes == 0) return buffer_;
    if (!cl.info.host_unified_memory) {
        cl.queue.enqueueFillBuffer(buffer_, cl_uint(0), 0, used_bytes);
        return buffer_;
    }
    if (fresh && fresh_pages_ == FreshPages::FaultWhereWritten)
        return buffer_;  // fresh pages are zero
    void* const mapped =
        cl.queue.enqueueMapBuffer(buffer_, CL_TRUE, CL_MAP_WRITE_INVALIDATE_REGION, 0, used_bytes);
    constexpr size_t kPart = size_t(1) << 20;
    tbb::parallel_for(size_t(0), (used_bytes + kPart - 1) / kPart, [&](size_t part) {
        const size_t begin = part * kPart;
        std::memset(static_cast<char*>(mapped) + begin, 0, std::min(kPart, used_bytes - begin));
    });
    cl.queue.enqueueUnmapMemObject(buffer_, mapped);
    return buffer_;
}

}  // namespace oclvox::detail
