// The library's exception hierarchy as Python classes (oclvox.Error and its subclasses), and the
// translator that raises them for the C++ exceptions leaving a binding.
#pragma once

#include <pybind11/pybind11.h>

namespace oclvox_python {

// Creates Error, InputError, GridError, DeviceError, KernelBuildError, OutputError and Cancelled in
// `module` and registers the translation from oclvox::Error subclasses.
void register_errors(pybind11::module_& module);

}  // namespace oclvox_python
