// The table of OpenVDB's functions, compiled with them (see vdb_module.hpp).
#include "field_vdb.hpp"
#include "vdb_module.hpp"

namespace oclvox::detail {

const VdbFunctions& linked_vdb_functions() {
    static const VdbFunctions functions = {
        static_cast<SparseField (*)(const std::string&)>(read_field_vdb),
        static_cast<SparseField (*)(const std::string&, const Grid&, double)>(read_field_vdb)};
    return functions;
}

}  // namespace oclvox::detail
