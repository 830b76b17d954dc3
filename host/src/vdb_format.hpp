// What every .vdb we write shares: the transform that puts OpenVDB's index (i, j, k) where our
// voxel (i, j, k) is, the grid's placement as metadata, and the atomic file write. Only the
// .vdb writers include this (it pulls in OpenVDB's headers).
#pragma once

#include <functional>
#include <string>

#include "oclvox/oclvox.hpp"
#include "openvdb_headers.hpp"

namespace oclvox::detail {

// OpenVDB's index space has its sample (i, j, k) at index point (i, j, k); ours has voxel
// (i, j, k) centred at origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size. So the transform scales
// by voxel_size and translates to vdb_index_origin (writers.hpp): the same integer (i, j, k)
// addresses the same voxel in both, and world positions agree.
openvdb::math::Transform::Ptr voxel_centre_transform(const Grid& grid);

// Sets `vdb`'s transform, name and class, and records our grid as metadata: "oclvox_origin"
// (Vec3d), "oclvox_voxel_size" (double) and "oclvox_dims" (Vec3i), so the exact box can be
// recovered even where the tree holds no voxel.
void place_vdb_grid(openvdb::GridBase& vdb, const Grid& grid, const std::string& name,
                    openvdb::GridClass grid_class);

// Writes one grid as a .vdb file (compression "active values") through a temporary file renamed
// into place (OutputError), calling before_rename (if set) once the bytes are written: a throw
// there leaves no file.
void write_vdb_file(const std::string& path, const openvdb::GridBase::Ptr& vdb,
                    const std::function<void()>& before_rename = {});

}  // namespace oclvox::detail
