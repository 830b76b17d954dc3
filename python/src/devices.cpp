#include "devices.hpp"

#include <pybind11/pybind11.h>

#include <map>

namespace py = pybind11;

namespace oclvox_python {
namespace {

std::mutex cache_mutex;
std::map<std::string, std::shared_ptr<SharedDevice>> cache;

}  // namespace

std::shared_ptr<SharedDevice> shared_device(const std::string& selector) {
    // The GIL goes first, the cache lock second, so a thread holding the lock while it compiles
    // kernels never waits for a thread that holds the GIL.
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(cache_mutex);
    auto found = cache.find(selector);
    if (found != cache.end()) return found->second;
    auto device = std::make_shared<SharedDevice>(oclvox::Device::open(selector));
    cache.emplace(selector, device);
    return device;
}

void forget_devices() {
    std::map<std::string, std::shared_ptr<SharedDevice>> dropped;
    {
        py::gil_scoped_release release;
        std::lock_guard<std::mutex> lock(cache_mutex);
        dropped.swap(cache);
    }
    // A device still in use by another thread lives on through that thread's shared_ptr.
    py::gil_scoped_release release;
    dropped.clear();
}

}  // namespace oclvox_python
