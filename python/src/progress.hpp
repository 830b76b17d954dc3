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
    // `callback`: None, or a callable taking (bricks_done, bricks_total); a result that is not
    // None and is false cancels the run.
    explicit ProgressBridge(pybind11::object callback);

    // For VoxelizeOptions::progress. It refers to this bridge, which must outlive the run.
    oclvox::ProgressCallback callback();

    // After a run threw oclvox::Cancelled: if the cancel came from a Python exception (raised by
    // the callback or by a signal handler such as KeyboardInterrupt), throws that instead.
    void rethrow_python_error();

  private:
    bool report(uint64_t done, uint64_t total);

    pybind11::object callback_;
    std::optional<pybind11::error_already_set> error_;
};

}  // namespace oclvox_python
