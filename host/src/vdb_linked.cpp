// A static liboclvox links OpenVDB's functions in (see vdb_module.hpp).
#include "vdb_module.hpp"

namespace oclvox::detail {

const VdbFunctions& vdb_functions_to_read(const std::string&) {
    return linked_vdb_functions();
}

}  // namespace oclvox::detail
