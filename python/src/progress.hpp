// The bridge between the library's progress callback, called on the calling thread while the GIL
// is released, and Python: a user callback `progress(done, total)` and Python's signal handlers
// (so Ctrl-C stops a long run).
#pragma once

#include <pybind11/pybind11.h>

#include <oclvox/oclvox.hpp>
#include <optional>

namespace oclvox_python {

class ProgressBridge {
  public:
    // `callback`: None, or a callable taking (done, total); a result that is not None and is
    // false cancels the run.
    explicit ProgressBridge(pybind11::object callback);

    // For the options' progress callback. It refers to this bridge, which must outlive the run.
    oclvox::ProgressCallback callback();

    // Runs work(callback()) with the GIL released. If the run is cancelled by a Python exception
    // (raised by the callback or by a signal handler such as KeyboardInterrupt), that exception
    // is raised instead of oclvox.Cancelled.
    template <typename Work>
    auto run_released(Work&& work) {
        try {
            pybind11::gil_scoped_release release;
            return work(callback());
        } catch (const oclvox::Cancelled&) {
            rethrow_python_error();
            throw;
        }
    }

  private:
    // After a run threw oclvox::Cancelled: throws the Python exception that caused it, if any.
    void rethrow_python_error();

    bool report(uint64_t done, uint64_t total);

    pybind11::object callback_;
    std::optional<pybind11::error_already_set> error_;
};

}  // namespace oclvox_python
