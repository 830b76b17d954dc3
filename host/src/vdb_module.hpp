// OpenVDB's part of the library, its .vdb reader, reached through one table of functions.
// Debian's libopenvdb is linked with BIND_NOW: loading it binds 52,402 symbols, about 30 ms of
// every process on the 2-core VM, whether or not the run reads a .vdb. So the shared liboclvox
// leaves it out, and loads it with these functions (the module liboclvox_vdb, beside liboclvox) on
// the first .vdb read; a static liboclvox (the Python wheel, the tests) links them in. (.vdb files
// are written without OpenVDB: vdb_stream.hpp.)
#pragma once

#include <string>

#include "oclvox/field.hpp"

namespace oclvox::detail {

// The module and liboclvox are built together; the struct changes with them.
struct VdbFunctions {
    SparseField (*read_field)(const std::string& path);
    SparseField (*read_field_onto)(const std::string& path, const Grid& lattice,
                                   double band_voxels);
};

// The table of the functions compiled beside it (field_vdb.cpp's readers).
const VdbFunctions& linked_vdb_functions();

// The table, loaded on first use where it is not linked in. Throws InputError naming `path` and
// why the module could not be loaded.
const VdbFunctions& vdb_functions_to_read(const std::string& path);

}  // namespace oclvox::detail
