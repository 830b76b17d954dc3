// The OpenCL side of Device: discovery, errors with status names, and programs compiled once per
// context and cached on disk (keyed by source hash, device, driver and build options).
#pragma once

#define CL_HPP_ENABLE_EXCEPTIONS
#include <CL/opencl.hpp>
#include <map>
#include <string>

#include "kernel_sources.hpp"
#include "oclvox/oclvox.hpp"

namespace oclvox::detail {

// "CL_OUT_OF_RESOURCES" for -5, and so on; "CL_UNKNOWN_ERROR(<code>)" otherwise.
std::string cl_status_name(cl_int status);

// DeviceError naming the failed call, its status and what oclvox was doing.
[[noreturn]] void throw_device_error(const cl::Error& error, const std::string& doing);

}  // namespace oclvox::detail

namespace oclvox {

struct Device::Impl {
    DeviceInfo info;
    cl::Device device;
    cl::Context context;
    cl::CommandQueue queue;
    std::map<std::string, cl::Program> programs;  // by source hash: built once per context

    // The built program for `source`: from this context's cache, else the disk cache, else
    // compiled (and then stored on disk). Throws KernelBuildError with the build log.
    const cl::Program& program(const detail::KernelSource& source);
};

}  // namespace oclvox
