// The entry of the module liboclvox_vdb (see vdb_module.hpp): what the shared liboclvox looks up
// once it has loaded the module.
#include "vdb_module.hpp"

extern "C" __attribute__((visibility("default"))) const oclvox::detail::VdbFunctions*
oclvox_vdb_functions() {
    return &oclvox::detail::linked_vdb_functions();
}
