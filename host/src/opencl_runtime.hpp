// The OpenCL side of Device: discovery, errors with status names, and programs compiled once per
// context and cached on disk (keyed by source hash, device, driver and build options).
#pragma once

#define CL_HPP_ENABLE_EXCEPTIONS
#include <CL/opencl.hpp>
#include <algorithm>
#include <functional>
#include <map>
#include <string>
#include <utility>

#include "kernel_sources.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// "CL_OUT_OF_RESOURCES" for -5, and so on; "CL_UNKNOWN_ERROR(<code>)" otherwise.
std::string cl_status_name(cl_int status);

// DeviceError naming the failed call, its status and what oclvox was doing.
[[noreturn]] void throw_device_error(const cl::Error& error, const std::string& doing);

// A fixed work-group size for `kernel`, queried from the kernel and the device rather than
// assumed. Some drivers (PoCL among them) compile a kernel once per work-group size, so letting
// the driver pick one per launch size would recompile on almost every launch.
size_t work_group_size(const cl::Kernel& kernel, const cl::Device& device);

// The options every program is built with on a device whose CL_DEVICE_SINGLE_FP_CONFIG is
// `single_fp_config`. Part of the determinism contract: "-cl-std=CL1.2", never fast-math or
// -cl-mad-enable (the kernels also say FP_CONTRACT OFF), plus
// -cl-fp32-correctly-rounded-divide-sqrt exactly when the device reports
// CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT (asking for it elsewhere is an invalid build option). The
// bit-for-bit kernels do not depend on it (they divide only through meshing_math.h's exact
// om_divide); it makes the winding number's divisions and square roots IEEE where available.
// A device of `type` CPU also gets -DOV_WIDE_BLOCKS: the surface kernels test a block's voxels 16
// lanes at a time, which a CPU's vector unit does about as fast as 4 (the same bits; on a GPU a
// work item's 16 lanes are 16 scalar operations, and its per-row skipping pays).
std::string build_options(cl_device_fp_config single_fp_config, cl_device_type type);

// Launches `kernel` over at least n items in groups of `group`; kernels skip the padding items.
void launch(const cl::CommandQueue& queue, const cl::Kernel& kernel, uint64_t n, size_t group);

// Sets kernel arguments first, first + 1, ... to `args`, in order.
template <typename... Args>
void set_args(cl::Kernel& kernel, cl_uint first, const Args&... args) {
    (kernel.setArg(first++, args), ...);
}

// Runs items [0, n) through `enqueue(first, count)`, which sets a slice's arguments and enqueues
// it: the one way every kernel over many items is launched. Slices are multiples of `group` (but
// the last), at most `max_slice` items (2^22 unless a kernel's items are long) so no single
// enqueue is enormous. Without `report` nothing waits between slices. With it, each slice is
// finished and then reported as report(items done, n), and slices are sized towards
// kSliceSeconds each, starting small: an item costs microseconds on a CPU device and nanoseconds
// on a GPU, and a cancel can only take effect between slices. The price is one queue round trip
// per slice.
constexpr double kSliceSeconds = 0.1;
constexpr uint64_t kMaxSliceItems = uint64_t(1) << 22;
void run_sliced(const cl::CommandQueue& queue, uint64_t n, size_t group,
                const std::function<void(uint64_t first, uint64_t count)>& enqueue,
                const std::function<void(uint64_t done, uint64_t total)>& report,
                uint64_t max_slice = kMaxSliceItems);

// A read-only buffer holding `data` (written without blocking). Zero-length buffers are invalid
// in OpenCL, so an empty vector gets a one-element buffer.
template <typename T, typename Allocator>
cl::Buffer upload(const cl::Context& context, const cl::CommandQueue& queue,
                  const std::vector<T, Allocator>& data) {
    const size_t bytes = std::max<size_t>(1, data.size()) * sizeof(T);
    cl::Buffer buffer(context, CL_MEM_READ_ONLY, bytes);
    if (!data.empty())
        queue.enqueueWriteBuffer(buffer, CL_FALSE, 0, data.size() * sizeof(T), data.data());
    return buffer;
}

// Calls f(pointer) with the first `count` elements of `buffer` mapped with `flags`, then unmaps
// it, also when f throws. Shared by read_mapped and write_mapped.
template <typename T, typename F>
void with_mapped(const cl::CommandQueue& queue, const cl::Buffer& buffer, cl_map_flags flags,
                 size_t count, F&& f) {
    if (count == 0) return;  // a mapping of no bytes is invalid
    void* mapped = queue.enqueueMapBuffer(buffer, CL_TRUE, flags, 0, count * sizeof(T));
    try {
        f(static_cast<T*>(mapped));
    } catch (...) {
        queue.enqueueUnmapMemObject(buffer, mapped);
        throw;
    }
    queue.enqueueUnmapMemObject(buffer, mapped);
}

// Calls f(pointer) with the first `count` elements of `buffer` mapped for reading. A CPU device
// maps the buffer itself (no copy into fresh host pages, which fault in at several microseconds a
// page); a GPU driver makes the same transfer a read would.
template <typename T, typename F>
void read_mapped(const cl::CommandQueue& queue, const cl::Buffer& buffer, size_t count, F&& f) {
    with_mapped<const T>(queue, buffer, CL_MAP_READ, count, std::forward<F>(f));
}

// Calls fill(pointer) to write the first `count` elements of `buffer` where the device maps them:
// data made on the way (a reordered copy, say) then needs no host copy of its own beside the
// buffer.
template <typename T, typename F>
void write_mapped(const cl::CommandQueue& queue, const cl::Buffer& buffer, size_t count, F&& fill) {
    with_mapped<T>(queue, buffer, CL_MAP_WRITE_INVALIDATE_REGION, count, std::forward<F>(fill));
}

}  // namespace oclvox::detail

namespace oclvox {

struct Device::Impl {
    DeviceInfo info;
    cl::Device device;
    cl::Context context;
    cl::CommandQueue queue;
    std::string build_options;                    // detail::build_options for this device
    std::map<std::string, cl::Program> programs;  // by source hash: built once per context
    std::function<void(const Device::KernelCompile&)> on_compile;  // may be empty

    // The built program for `source`: from this context's cache, else the disk cache, else
    // compiled (and then stored on disk). Throws KernelBuildError with the build log.
    const cl::Program& program(const detail::KernelSource& source);
};

}  // namespace oclvox

namespace oclvox::detail {

// The OpenCL objects of a device, for the library's algorithms (the public Device hides them).
struct DeviceAccess {
    static Device::Impl& impl(Device& device) { return *device.impl_; }
};
inline Device::Impl& device_impl(Device& device) {
    return DeviceAccess::impl(device);
}

// A read-only buffer of `data` that a device working in the host's memory reads where it lies:
// copying into a fresh buffer costs a page fault per 4 KiB there, more than most kernels reading
// it. Other devices get a copy in their own memory (upload). So `data` must stay alive and
// unchanged while the buffer is in use.
template <typename T, typename Allocator>
cl::Buffer read_in_place(const Device::Impl& cl, const std::vector<T, Allocator>& data) {
    if (!cl.info.host_unified_memory || data.empty()) return upload(cl.context, cl.queue, data);
    return cl::Buffer(cl.context, CL_MEM_READ_ONLY | CL_MEM_USE_HOST_PTR, data.size() * sizeof(T),
                      const_cast<T*>(data.data()));
}

}  // namespace oclvox::detail
