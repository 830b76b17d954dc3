// The entry of the module liboclvox_vdb (see vdb_module.hpp): what the shared liboclvox looks up
// once it has loaded the module.
#include "vdb_module.hpp"

// Named with the version (OCLVOX_VDB_ENTRY, from CMake): a module of another version is not
// taken for this one's.
extern "C" __attribute__((visibility("default"))) const oclvox::detail::VdbFunctions*
OCLVOX_VDB_ENTRY() {
    return &oclvox::detail::linked_vdb_functions();
}
