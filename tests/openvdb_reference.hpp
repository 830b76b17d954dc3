// The independent reference of the .vdb byte-for-byte tests (test_writers.cpp, test_sdf.cpp):
// grids built through OpenVDB's own API and written by OpenVDB's own writer, placed and described
// from our Grid alone (never from our files), so a wrong transform or metadata value shows.
#pragma once

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <sstream>
#include <string>

#include "oclvox/oclvox.hpp"

namespace oclvox::test {

// Name and class; index (i, j, k) at the centre of our voxel (i, j, k), origin + (i + 0.5) *
// voxel_size; our grid as metadata (oclvox_origin, oclvox_voxel_size, oclvox_dims).
inline void place_as_our_vdb_files_do(openvdb::GridBase& grid, const Grid& g,
                                      const std::string& name, openvdb::GridClass grid_class) {
    grid.setName(name);
    grid.setGridClass(grid_class);
    const openvdb::math::Transform::Ptr transform =
        openvdb::math::Transform::createLinearTransform(g.voxel_size);
    transform->postTranslate(openvdb::Vec3d(g.origin[0] + 0.5 * g.voxel_size,
                                            g.origin[1] + 0.5 * g.voxel_size,
                                            g.origin[2] + 0.5 * g.voxel_size));
    grid.setTransform(transform);
    grid.insertMeta("oclvox_origin",
                    openvdb::Vec3DMetadata(openvdb::Vec3d(g.origin[0], g.origin[1], g.origin[2])));
    grid.insertMeta("oclvox_voxel_size", openvdb::DoubleMetadata(g.voxel_size));
    grid.insertMeta("oclvox_dims", openvdb::Vec3IMetadata(openvdb::Vec3i(
                                       int(g.dims[0]), int(g.dims[1]), int(g.dims[2]))));
}

// The file io::Stream writes of `grid` with the active-mask compression (its statistics metadata
// worked out by OpenVDB).
inline std::string written_by_openvdb(const openvdb::GridBase::ConstPtr& grid) {
    std::ostringstream out;
    openvdb::io::Stream stream(out);
    stream.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK);
    stream.write(openvdb::GridCPtrVec{grid});
    return out.str();
}

}  // namespace oclvox::test
