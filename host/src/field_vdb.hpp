// The OpenVDB reader behind read_sparse_field (kept apart so only one file needs OpenVDB's headers;
// .vdb files are written without OpenVDB, see vdb_stream.hpp).
#pragma once

#include <string>

#include "oclvox/field.hpp"

namespace oclvox::detail {

// See read_sparse_field (oclvox/sdf.hpp), both forms. Throw InputError.
SparseField read_field_vdb(const std::string& path);
SparseField read_field_vdb(const std::string& path, const Grid& lattice, double band_voxels);

}  // namespace oclvox::detail
