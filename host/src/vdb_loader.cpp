// The shared liboclvox loads OpenVDB's functions on the first .vdb (see vdb_module.hpp): the
// module liboclvox_vdb from the folder liboclvox was loaded from (the build tree, or the installed
// library's folder), else wherever the dynamic loader finds it.
#include <dlfcn.h>

#include <mutex>

#include "file_names.hpp"
#include "vdb_module.hpp"

namespace oclvox::detail {

namespace {

struct Loaded {
    const VdbFunctions* functions = nullptr;
    std::string why;  // the reason functions is null
};

// The module's path beside this library, or "" where the loader cannot say where it is.
std::string module_beside_this_library() {
    Dl_info info{};
    if (dladdr(reinterpret_cast<void*>(&module_beside_this_library), &info) == 0 || !info.dli_fname)
        return "";
    return folder_of(info.dli_fname) + "/" OCLVOX_VDB_MODULE_FILE;
}

const Loaded& loaded() {
    static Loaded result;
    static std::once_flag once;
    std::call_once(once, [] {
        const std::string beside = module_beside_this_library();
        void* module = beside.empty() ? nullptr : dlopen(beside.c_str(), RTLD_NOW | RTLD_LOCAL);
        std::string why = module || beside.empty() ? "" : std::string(dlerror()) + "; ";
        if (!module) {
            module = dlopen(OCLVOX_VDB_MODULE_FILE, RTLD_NOW | RTLD_LOCAL);
            if (!module) why += dlerror();
        }
        if (!module) {
            result.why = "OpenVDB support, the module " OCLVOX_VDB_MODULE_FILE
                         " beside liboclvox, could not be loaded: " +
                         why;
            return;
        }
        using Entry = const VdbFunctions* (*)();
        const auto entry = reinterpret_cast<Entry>(dlsym(module, OCLVOX_VDB_ENTRY_NAME));
        if (!entry) {
            result.why = "the module " OCLVOX_VDB_MODULE_FILE " has no " OCLVOX_VDB_ENTRY_NAME
                         ": it is from another version of oclvox";
            return;
        }
        result.functions = entry();
    });
    return result;
}

}  // namespace

const VdbFunctions& vdb_functions_to_read(const std::string& path) {
    const Loaded& module = loaded();
    if (!module.functions) throw InputError("cannot read " + path + ": " + module.why);
    return *module.functions;
}

}  // namespace oclvox::detail
