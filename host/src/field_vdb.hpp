// The OpenVDB writer behind write_field and the reader behind read_sparse_field (kept apart so
// only one file needs OpenVDB's headers).
#pragma once

#include <string>

#include "oclvox/field.hpp"
#include "progress.hpp"

namespace oclvox::detail {

// A level-set FloatGrid named "sdf" (see write_field in oclvox/sdf.hpp). Throws OutputError.
// The field's layers come from layer(k, out) in order, 8 (a leaf's height) held at a time;
// band_voxels <= 0 takes the largest |value| (every sample is kept in the tree until it is known).
void write_field_vdb(const std::string& path, const Grid& grid, double band_voxels,
                     const FieldLayer& layer, ProgressPhases& progress);
// See read_sparse_field (oclvox/sdf.hpp), both forms. Throw InputError.
SparseField read_field_vdb(const std::string& path);
SparseField read_field_vdb(const std::string& path, const Grid& lattice, double band_voxels);

}  // namespace oclvox::detail
