#include "progress.hpp"

namespace py = pybind11;

namespace oclvox_python {

ProgressBridge::ProgressBridge(py::object callback) : callback_(std::move(callback)) {
    if (!callback_.is_none() && !PyCallable_Check(callback_.ptr()))
        throw py::type_error("progress must be callable as progress(done, total), or None");
}

oclvox::ProgressCallback ProgressBridge::callback() {
    return [this](uint64_t done, uint64_t total) { return report(done, total); };
}

bool ProgressBridge::report(uint64_t done, uint64_t total) {
    py::gil_scoped_acquire acquire;
    try {
        // Signal handlers run only on the main thread; elsewhere this returns 0 at once.
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        if (callback_.is_none()) return true;
        const py::object result = callback_(done, total);
        if (result.is_none()) return true;
        const int truth = PyObject_IsTrue(result.ptr());
        if (truth < 0) throw py::error_already_set();
        return truth != 0;
    } catch (py::error_already_set& e) {
        error_.emplace(std::move(e));
        return false;
    }
}

void ProgressBridge::rethrow_python_error() {
    if (!error_) return;
    py::error_already_set error = std::move(*error_);
    error_.reset();
    throw error;
}

}  // namespace oclvox_python
