// The zeroed slot buffers of device_batches.hpp.
#include "device_batches.hpp"

#include <cstring>

namespace oclvox::detail {

const cl::Buffer& ZeroedSlotBuffer::get(const Device::Impl& cl, size_t slots, size_t used) {
    const cl::Buffer& buffer = buffer_.get(cl.context, slots);
    const size_t used_bytes = std::min(used, slots) * bytes_per_slot_;
    if (used_bytes == 0) return buffer;
    if (!cl.info.host_unified_memory) {
        cl.queue.enqueueFillBuffer(buffer, cl_uint(0), 0, used_bytes);
        return buffer;
    }
    void* const mapped =
        cl.queue.enqueueMapBuffer(buffer, CL_TRUE, CL_MAP_WRITE_INVALIDATE_REGION, 0, used_bytes);
    constexpr size_t kPart = size_t(1) << 20;
    tbb::parallel_for(size_t(0), (used_bytes + kPart - 1) / kPart, [&](size_t part) {
        const size_t begin = part * kPart;
        std::memset(static_cast<char*>(mapped) + begin, 0, std::min(kPart, used_bytes - begin));
    });
    cl.queue.enqueueUnmapMemObject(buffer, mapped);
    return buffer;
}

}  // namespace oclvox::detail
