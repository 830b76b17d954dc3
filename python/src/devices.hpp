// OpenCL devices for the Python module: opened once per selector and kept for the life of the
// interpreter (opening one builds or loads its kernels, which costs far more than most runs), and
// used by one call at a time, since several Python threads may run device work at once with the
// GIL released.
#pragma once

#include <memory>
#include <mutex>
#include <oclvox/oclvox.hpp>
#include <string>

namespace oclvox_python {

struct SharedDevice {
    explicit SharedDevice(oclvox::Device opened) : device(std::move(opened)) {}
    oclvox::Device device;
    std::mutex in_use;  // held for the whole of each call that runs work on `device`
};

// The device for `selector` (as oclvox::Device::open takes it), opened on first use. Call with the
// GIL held; it is released while a device is being opened. Throws oclvox::DeviceError.
std::shared_ptr<SharedDevice> shared_device(const std::string& selector);

// Drops every cached device (at interpreter exit, before Python's own teardown).
void forget_devices();

}  // namespace oclvox_python
