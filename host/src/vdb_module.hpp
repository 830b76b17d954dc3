// OpenVDB's part of the library, reached through one table of functions. Debian's libopenvdb is
// linked with BIND_NOW: loading it binds 52,402 symbols, about 30 ms of every process on the
// 2-core VM, whether or not the run reads or writes a .vdb. So the shared liboclvox leaves it out,
// and loads it with these functions (the module liboclvox_vdb, beside liboclvox) on the first
// .vdb that needs them; a static liboclvox (the Python wheel, the tests) links them in.
// (Occupancy and sparse level-set .vdb files are written without OpenVDB: write_vdb.cpp,
// write_level_set_vdb.cpp.)
#pragma once

#include <string>

#include "oclvox/field.hpp"
#include "progress.hpp"

namespace oclvox::detail {

// The module and liboclvox are built together; the struct changes with them.
struct VdbFunctions {
    void (*write_field)(const std::string& path, const Grid& grid, double band_voxels,
                        const FieldLayer& layer, ProgressPhases& progress);
    SparseField (*read_field)(const std::string& path);
    SparseField (*read_field_onto)(const std::string& path, const Grid& lattice,
                                   double band_voxels);
};

// The table of the functions compiled beside it (field_vdb.cpp).
const VdbFunctions& linked_vdb_functions();

// The table, loaded on first use where it is not linked in. Throws OutputError (writing) or
// InputError (reading) naming `path` and why the module could not be loaded.
const VdbFunctions& vdb_functions_to_write(const std::string& path);
const VdbFunctions& vdb_functions_to_read(const std::string& path);

}  // namespace oclvox::detail
