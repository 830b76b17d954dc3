// Device discovery, selection, error reporting and program caching.
#include "opencl_runtime.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <sstream>

#include "atomic_file.hpp"
#include "file_names.hpp"
#include "timing.hpp"

namespace oclvox::detail {

std::string cl_status_name(cl_int status) {
    switch (status) {
#define OV_STATUS(name) \
    case name:          \
        return #name;
        OV_STATUS(CL_SUCCESS)
        OV_STATUS(CL_DEVICE_NOT_FOUND)
        OV_STATUS(CL_DEVICE_NOT_AVAILABLE)
        OV_STATUS(CL_COMPILER_NOT_AVAILABLE)
        OV_STATUS(CL_MEM_OBJECT_ALLOCATION_FAILURE)
        OV_STATUS(CL_OUT_OF_RESOURCES)
        OV_STATUS(CL_OUT_OF_HOST_MEMORY)
        OV_STATUS(CL_PROFILING_INFO_NOT_AVAILABLE)
        OV_STATUS(CL_MEM_COPY_OVERLAP)
        OV_STATUS(CL_IMAGE_FORMAT_MISMATCH)
        OV_STATUS(CL_IMAGE_FORMAT_NOT_SUPPORTED)
        OV_STATUS(CL_BUILD_PROGRAM_FAILURE)
        OV_STATUS(CL_MAP_FAILURE)
        OV_STATUS(CL_MISALIGNED_SUB_BUFFER_OFFSET)
        OV_STATUS(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST)
        OV_STATUS(CL_COMPILE_PROGRAM_FAILURE)
        OV_STATUS(CL_LINKER_NOT_AVAILABLE)
        OV_STATUS(CL_LINK_PROGRAM_FAILURE)
        OV_STATUS(CL_DEVICE_PARTITION_FAILED)
        OV_STATUS(CL_KERNEL_ARG_INFO_NOT_AVAILABLE)
        OV_STATUS(CL_INVALID_VALUE)
        OV_STATUS(CL_INVALID_DEVICE_TYPE)
        OV_STATUS(CL_INVALID_PLATFORM)
        OV_STATUS(CL_INVALID_DEVICE)
        OV_STATUS(CL_INVALID_CONTEXT)
        OV_STATUS(CL_INVALID_QUEUE_PROPERTIES)
        OV_STATUS(CL_INVALID_COMMAND_QUEUE)
        OV_STATUS(CL_INVALID_HOST_PTR)
        OV_STATUS(CL_INVALID_MEM_OBJECT)
        OV_STATUS(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR)
        OV_STATUS(CL_INVALID_IMAGE_SIZE)
        OV_STATUS(CL_INVALID_SAMPLER)
        OV_STATUS(CL_INVALID_BINARY)
        OV_STATUS(CL_INVALID_BUILD_OPTIONS)
        OV_STATUS(CL_INVALID_PROGRAM)
        OV_STATUS(CL_INVALID_PROGRAM_EXECUTABLE)
        OV_STATUS(CL_INVALID_KERNEL_NAME)
        OV_STATUS(CL_INVALID_KERNEL_DEFINITION)
        OV_STATUS(CL_INVALID_KERNEL)
        OV_STATUS(CL_INVALID_ARG_INDEX)
        OV_STATUS(CL_INVALID_ARG_VALUE)
        OV_STATUS(CL_INVALID_ARG_SIZE)
        OV_STATUS(CL_INVALID_KERNEL_ARGS)
        OV_STATUS(CL_INVALID_WORK_DIMENSION)
        OV_STATUS(CL_INVALID_WORK_GROUP_SIZE)
        OV_STATUS(CL_INVALID_WORK_ITEM_SIZE)
        OV_STATUS(CL_INVALID_GLOBAL_OFFSET)
        OV_STATUS(CL_INVALID_EVENT_WAIT_LIST)
        OV_STATUS(CL_INVALID_EVENT)
        OV_STATUS(CL_INVALID_OPERATION)
        OV_STATUS(CL_INVALID_GL_OBJECT)
        OV_STATUS(CL_INVALID_BUFFER_SIZE)
        OV_STATUS(CL_INVALID_MIP_LEVEL)
        OV_STATUS(CL_INVALID_GLOBAL_WORK_SIZE)
        OV_STATUS(CL_INVALID_PROPERTY)
        OV_STATUS(CL_INVALID_IMAGE_DESCRIPTOR)
        OV_STATUS(CL_INVALID_COMPILER_OPTIONS)
        OV_STATUS(CL_INVALID_LINKER_OPTIONS)
        OV_STATUS(CL_INVALID_DEVICE_PARTITION_COUNT)
#undef OV_STATUS
        case -1001:
            return "CL_PLATFORM_NOT_FOUND_KHR";
        default:
            return "CL_UNKNOWN_ERROR(" + std::to_string(status) + ")";
    }
}

size_t work_group_size(const cl::Kernel& kernel, const cl::Device& device) {
    const size_t max = kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(device);
    const size_t multiple = std::max<size_t>(
        1, kernel.getWorkGroupInfo<CL_KERNEL_PREFERRED_WORK_GROUP_SIZE_MULTIPLE>(device));
    size_t size = multiple * std::max<size_t>(1, 64 / multiple);
    while (size > max && size > 1) size /= 2;
    return std::max<size_t>(1, size);
}

std::string build_options(cl_device_fp_config single_fp_config, cl_device_type type) {
    std::string options = "-cl-std=CL1.2";
    if (single_fp_config & CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT)
        options += " -cl-fp32-correctly-rounded-divide-sqrt";
    if (type & CL_DEVICE_TYPE_CPU) options += " -DOV_WIDE_BLOCKS";
    return options;
}

void launch(const cl::CommandQueue& queue, const cl::Kernel& kernel, uint64_t n, size_t group) {
    const size_t global = size_t((n + group - 1) / group * group);
    queue.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(global), cl::NDRange(group));
}

void run_sliced(const cl::CommandQueue& queue, uint64_t n, size_t group,
                const std::function<void(uint64_t first, uint64_t count)>& enqueue,
                const std::function<void(uint64_t done, uint64_t total)>& report,
                uint64_t max_slice) {
    constexpr uint64_t kFirstSlice = uint64_t(1) << 12;
    const uint64_t unit = std::max<uint64_t>(1, group);
    auto whole_groups = [&](uint64_t items) {
        return std::clamp(items / unit * unit, unit, std::max(unit, max_slice / unit * unit));
    };
    uint64_t slice = whole_groups(report ? kFirstSlice : max_slice);
    for (uint64_t first = 0; first < n;) {
        const uint64_t count = std::min(slice, n - first);
        const auto start = Clock::now();
        enqueue(first, count);
        first += count;
        if (!report) continue;
        queue.finish();
        const double seconds = seconds_since(start);
        report(first, n);
        // Towards kSliceSeconds, by at most 4x per slice so one noisy timing cannot swing it far.
        if (count == slice) {
            const double scale = seconds > 0 ? kSliceSeconds / seconds : 4.0;
            slice = whole_groups(uint64_t(double(slice) * std::clamp(scale, 0.25, 4.0)));
        }
    }
}

void throw_device_error(const cl::Error& error, const std::string& doing) {
    throw DeviceError("OpenCL error while " + doing + ": " + (error.what() ? error.what() : "?") +
                      " returned " + cl_status_name(error.err()));
}

}  // namespace oclvox::detail

namespace oclvox {

namespace {

using detail::Clock;
using detail::seconds_since;
using detail::throw_device_error;

// Fault injection for tests/fault_test.sh: OCLVOX_FAULT_BUILD_OPTIONS is appended to the build
// options (bypassing the binary cache), so a test can make the kernel build fail.
const char* injected_build_options() {
    static const char* const options = std::getenv("OCLVOX_FAULT_BUILD_OPTIONS");
    return options;
}

std::string type_name(cl_device_type type) {
    if (type & CL_DEVICE_TYPE_GPU) return "GPU";
    if (type & CL_DEVICE_TYPE_CPU) return "CPU";
    if (type & CL_DEVICE_TYPE_ACCELERATOR) return "ACCELERATOR";
    return "OTHER";
}

struct Found {
    cl::Platform platform;
    cl::Device device;
    DeviceInfo info;
};

std::vector<Found> all_devices() {
    std::vector<cl::Platform> platforms;
    try {
        cl::Platform::get(&platforms);
    } catch (const cl::Error& e) {
        // The ICD loader reports "no platform" as an error code rather than an empty list.
        if (e.err() != -1001) throw_device_error(e, "listing OpenCL platforms");
    }
    if (platforms.empty())
        throw DeviceError(
            "no OpenCL platform found: install an OpenCL driver (an ICD such as pocl-opencl-icd "
            "for CPUs, or your GPU vendor's driver)");
    std::vector<Found> found;
    for (size_t p = 0; p < platforms.size(); ++p) {
        std::vector<cl::Device> devices;
        try {
            platforms[p].getDevices(CL_DEVICE_TYPE_ALL, &devices);
        } catch (const cl::Error& e) {
            if (e.err() == CL_DEVICE_NOT_FOUND) continue;
            throw_device_error(e, "listing the devices of platform " + std::to_string(p));
        }
        for (size_t d = 0; d < devices.size(); ++d) {
            try {
                DeviceInfo info;
                info.platform = platforms[p].getInfo<CL_PLATFORM_NAME>();
                info.name = devices[d].getInfo<CL_DEVICE_NAME>();
                info.vendor = devices[d].getInfo<CL_DEVICE_VENDOR>();
                info.version = devices[d].getInfo<CL_DEVICE_VERSION>();
                info.driver_version = devices[d].getInfo<CL_DRIVER_VERSION>();
                info.type = type_name(devices[d].getInfo<CL_DEVICE_TYPE>());
                info.global_memory = devices[d].getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
                info.max_alloc = devices[d].getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
                info.host_unified_memory =
                    devices[d].getInfo<CL_DEVICE_HOST_UNIFIED_MEMORY>() == CL_TRUE;
                info.id = std::to_string(p) + ":" + std::to_string(d);
                found.push_back({platforms[p], devices[d], info});
            } catch (const cl::Error& e) {
                throw_device_error(
                    e, "querying device " + std::to_string(p) + ":" + std::to_string(d));
            }
        }
    }
    if (found.empty()) throw DeviceError("OpenCL platforms exist but none has a device");
    return found;
}

std::string device_list_text(const std::vector<Found>& found) {
    std::string text;
    for (const Found& f : found)
        text += "\n  " + f.info.id + "  " + f.info.type + "  " + f.info.name + " (" +
                f.info.platform + ")";
    return text;
}

// "", "P:D", or a case-insensitive substring of "platform device".
const Found& select_device(const std::vector<Found>& found, const std::string& selector) {
    if (selector.empty()) {
        for (const Found& f : found)
            if (f.info.type == "GPU") return f;
        return found.front();
    }
    for (const Found& f : found)
        if (f.info.id == selector) return f;
    const std::string needle = detail::lowercase(selector);
    for (const Found& f : found)
        if (detail::lowercase(f.info.platform + " " + f.info.name).find(needle) !=
            std::string::npos)
            return f;
    throw DeviceError("no OpenCL device matches '" + selector +
                      "'; available:" + device_list_text(found));
}

// ---- on-disk program cache -----------------------------------------------------------------

std::string cache_folder() {
    if (const char* dir = std::getenv("OCLVOX_CACHE_DIR")) {
        const std::string d = dir;
        return d == "off" || d.empty() ? std::string() : d;
    }
    if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg)
        return std::string(xdg) + "/oclvox";
    if (const char* home = std::getenv("HOME"); home && *home)
        return std::string(home) + "/.cache/oclvox";
    return {};
}

// FNV-1a: a stable 64-bit key (std::hash promises no stability across builds).
uint64_t fnv1a(const std::string& s) {
    uint64_t h = 1469598103934665603ull;
    for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
    return h;
}

std::string cache_path(const Device::Impl& impl, const detail::KernelSource& source) {
    const DeviceInfo& info = impl.info;
    const std::string folder = cache_folder();
    if (folder.empty()) return {};
    const std::string key = std::string(source.sha256) + "|" + info.platform + "|" + info.name +
                            "|" + info.vendor + "|" + info.version + "|" + info.driver_version +
                            "|" + impl.build_options;
    char hex[17];
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(fnv1a(key)));
    return folder + "/" + source.name + "-" + hex + ".bin";
}

std::string build_log(const cl::Program& program, const cl::Device& device) {
    try {
        return program.getBuildInfo<CL_PROGRAM_BUILD_LOG>(device);
    } catch (const cl::Error&) {
        return "(no build log available)";
    }
}

// A cached binary that is missing, unreadable or rejected by the driver just means a rebuild.
bool load_cached(Device::Impl& impl, const std::string& path, cl::Program& out) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return false;
    std::vector<unsigned char> binary((std::istreambuf_iterator<char>(in)),
                                      std::istreambuf_iterator<char>());
    if (binary.empty()) return false;
    try {
        cl::Program program(impl.context, {impl.device}, cl::Program::Binaries{binary});
        program.build({impl.device}, impl.build_options.c_str());
        out = program;
        return true;
    } catch (const cl::Error&) {
        return false;
    }
}

void store_cached(const cl::Program& program, const std::string& path) {
    try {
        const auto binaries = program.getInfo<CL_PROGRAM_BINARIES>();
        if (binaries.empty() || binaries[0].empty()) return;
        const std::string folder = path.substr(0, path.rfind('/'));
        std::string mkdir = folder;  // create parents one by one
        for (size_t i = 1; i <= mkdir.size(); ++i)
            if (i == mkdir.size() || mkdir[i] == '/') ::mkdir(mkdir.substr(0, i).c_str(), 0755);
        detail::write_file_atomically(path, [&](std::ostream& os) {
            os.write(reinterpret_cast<const char*>(binaries[0].data()),
                     std::streamsize(binaries[0].size()));
        });
    } catch (const std::exception&) {
        // The cache is an optimisation: a read-only or full disk must not fail the run.
    }
}

}  // namespace

std::vector<DeviceInfo> list_devices() {
    std::vector<DeviceInfo> out;
    for (const Found& f : all_devices()) out.push_back(f.info);
    return out;
}

Device::Device(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Device::~Device() = default;
Device::Device(Device&&) noexcept = default;
Device& Device::operator=(Device&&) noexcept = default;
const DeviceInfo& Device::info() const {
    return impl_->info;
}
void Device::on_kernel_compile(std::function<void(const KernelCompile&)> callback) {
    impl_->on_compile = std::move(callback);
}

Device Device::open(const std::string& selector) {
    const std::vector<Found> found = all_devices();
    const Found& f = select_device(found, selector);
    auto impl = std::make_unique<Impl>();
    impl->info = f.info;
    impl->device = f.device;
    try {
        impl->context = cl::Context(f.device);
        impl->queue = cl::CommandQueue(impl->context, f.device);
        impl->build_options = detail::build_options(f.device.getInfo<CL_DEVICE_SINGLE_FP_CONFIG>(),
                                                    f.device.getInfo<CL_DEVICE_TYPE>());
    } catch (const cl::Error& e) {
        throw_device_error(e, "creating a context on " + f.info.name);
    }
    return Device(std::move(impl));
}

const cl::Program& Device::Impl::program(const detail::KernelSource& source) {
    auto it = programs.find(source.sha256);
    if (it != programs.end()) return it->second;

    const char* injected = injected_build_options();
    const std::string path = injected ? std::string() : cache_path(*this, source);
    const std::string options = injected ? build_options + " " + injected : build_options;
    cl::Program program;
    if (path.empty() || !load_cached(*this, path, program)) {
        const auto start = Clock::now();
        if (on_compile) on_compile({source.name, false, 0.0});
        try {
            program = cl::Program(context, std::string(source.text));
        } catch (const cl::Error& e) {
            throw_device_error(e, std::string("creating program ") + source.name);
        }
        try {
            program.build({device}, options.c_str());
        } catch (const cl::Error& e) {
            throw KernelBuildError("building kernels/" + std::string(source.name) + ".cl for " +
                                       info.name + " failed: " + detail::cl_status_name(e.err()),
                                   build_log(program, device));
        }
        if (!path.empty()) store_cached(program, path);
        if (on_compile) on_compile({source.name, true, seconds_since(start)});
    }
    return programs.emplace(source.sha256, program).first->second;
}

}  // namespace oclvox
