#include "errors.hpp"

#include <oclvox/oclvox.hpp>
#include <string>

namespace py = pybind11;

namespace oclvox_python {
namespace {

// The classes, created once at import. Kept as raw new references for the life of the process:
// the translator may run until the interpreter shuts down.
struct ErrorClasses {
    PyObject* error = nullptr;
    PyObject* input = nullptr;
    PyObject* grid = nullptr;
    PyObject* device = nullptr;
    PyObject* kernel_build = nullptr;
    PyObject* output = nullptr;
    PyObject* cancelled = nullptr;
};
ErrorClasses classes;

// A class `oclvox.<name>` deriving from every class in `bases`, with `doc` as its docstring.
PyObject* make_class(py::module_& module, const char* name, py::tuple bases, const char* doc) {
    const std::string qualified = "oclvox." + std::string(name);
    PyObject* type =
        PyErr_NewExceptionWithDoc(qualified.c_str(), doc, bases.ptr(), /*dict=*/nullptr);
    if (!type) throw py::error_already_set();
    module.add_object(name, py::handle(type));  // steals nothing: add_object increfs
    return type;
}

void raise(PyObject* type, const std::exception& error) {
    PyErr_SetString(type, error.what());
}

}  // namespace

void register_errors(py::module_& module) {
    // Where a Python built-in means the same thing, the class derives from it too, so code that
    // catches ValueError or OSError also catches ours.
    const py::handle exception(PyExc_Exception), value_error(PyExc_ValueError),
        runtime_error(PyExc_RuntimeError), os_error(PyExc_OSError);
    classes.error = make_class(module, "Error", py::make_tuple(exception),
                               "Base class of every error oclvox raises.");
    const py::handle error(classes.error);
    classes.input = make_class(
        module, "InputError", py::make_tuple(error, value_error),
        "The input mesh (file or arrays) is unusable: missing, malformed, NaN, no triangles, ...");
    classes.grid = make_class(
        module, "GridError", py::make_tuple(error, value_error),
        "The grid or the options cannot be used (zero or absurd size, memory limits, bad names).");
    classes.device = make_class(module, "DeviceError", py::make_tuple(error, runtime_error),
                                "An OpenCL call failed, or no (matching) device exists.");
    classes.kernel_build =
        make_class(module, "KernelBuildError", py::make_tuple(py::handle(classes.device)),
                   "A kernel failed to compile; .build_log holds the log.");
    classes.output = make_class(module, "OutputError", py::make_tuple(error, os_error),
                                "Writing a file failed (nothing is left under the final name).");
    classes.cancelled = make_class(module, "Cancelled", py::make_tuple(error),
                                   "The progress callback asked to stop.");

    // Most derived first.
    py::register_exception_translator([](std::exception_ptr pointer) {
        if (!pointer) return;
        try {
            std::rethrow_exception(pointer);
        } catch (const oclvox::KernelBuildError& e) {
            // The instance carries the compiler's log apart from the message.
            py::object instance =
                py::reinterpret_borrow<py::object>(classes.kernel_build)(py::str(e.what()));
            instance.attr("build_log") = py::str(e.build_log());
            PyErr_SetObject(classes.kernel_build, instance.ptr());
        } catch (const oclvox::DeviceError& e) {
            raise(classes.device, e);
        } catch (const oclvox::InputError& e) {
            raise(classes.input, e);
        } catch (const oclvox::GridError& e) {
            raise(classes.grid, e);
        } catch (const oclvox::OutputError& e) {
            raise(classes.output, e);
        } catch (const oclvox::Cancelled& e) {
            raise(classes.cancelled, e);
        } catch (const oclvox::Error& e) {
            raise(classes.error, e);
        }
    });
}

}  // namespace oclvox_python
