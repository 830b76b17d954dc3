// OpenVDB level-set output. OpenVDB's index space has sample (i, j, k) at index point (i, j, k);
// ours has it at the centre of voxel (i, j, k), origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size.
// So the transform scales by voxel_size and translates by origin + 0.5 * voxel_size: the same
// integer (i, j, k) addresses the same sample in both, and world positions agree.
#include "field_vdb.hpp"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/SignedFloodFill.h>

#include "atomic_file.hpp"

namespace oclvox::detail {

void write_field_vdb(const std::string& path, const ScalarField& field, double band_voxels) {
    openvdb::initialize();
    const Grid& g = field.grid;
    const float background = float(band_voxels * g.voxel_size);

    // Phase 1: grid, transform and metadata.
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
    openvdb::math::Transform::Ptr transform =
        openvdb::math::Transform::createLinearTransform(g.voxel_size);
    transform->postTranslate(openvdb::Vec3d(g.origin[0] + 0.5 * g.voxel_size,
                                            g.origin[1] + 0.5 * g.voxel_size,
                                            g.origin[2] + 0.5 * g.voxel_size));
    grid->setTransform(transform);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    grid->setName("sdf");
    grid->insertMeta("oclvox_band_voxels", openvdb::DoubleMetadata(band_voxels));

    // Phase 2: the narrow band as active voxels. The rest stays background, and the signed flood
    // fill then gives the inactive regions inside the surface the background's negative, as a
    // level set's tiles must have.
    openvdb::FloatGrid::Accessor access = grid->getAccessor();
    const int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
    for (int64_t k = 0; k < nz; ++k)
        for (int64_t j = 0; j < ny; ++j)
            for (int64_t i = 0; i < nx; ++i) {
                const float value = field.values[size_t(i + nx * (j + ny * k))];
                if (std::abs(value) < background)
                    access.setValue(openvdb::Coord(int(i), int(j), int(k)), value);
            }
    openvdb::tools::signedFloodFill(grid->tree());

    // Phase 3: the file.
    write_file_atomically(path, [&](std::ostream& out) {
        openvdb::io::Stream stream(out);
        stream.write(openvdb::GridCPtrVec{grid});
    });
}

}  // namespace oclvox::detail
