// OpenVDB level-set output: sample (i, j, k) of the field at OpenVDB index (i, j, k), placed by
// the shared voxel-centre transform (vdb_format.hpp).
#include "field_vdb.hpp"

#include <openvdb/tools/SignedFloodFill.h>

#include "vdb_format.hpp"

namespace oclvox::detail {

void write_field_vdb(const std::string& path, const ScalarField& field, double band_voxels,
                     ProgressPhases& progress) {
    openvdb::initialize();
    const Grid& g = field.grid;
    const float background = float(band_voxels * g.voxel_size);

    // Phase 1: grid, transform and metadata.
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
    place_vdb_grid(*grid, g, "sdf", openvdb::GRID_LEVEL_SET);
    grid->insertMeta("oclvox_band_voxels", openvdb::DoubleMetadata(band_voxels));

    // Phase 2: the narrow band as active voxels. The rest stays background, and the signed flood
    // fill then gives the inactive regions inside the surface the background's negative, as a
    // level set's tiles must have.
    // The band by layers, then the flood fill and the file (no progress of their own, estimated
    // at about the band's cost together).
    const size_t band = progress.add(2), file = progress.add(1);
    openvdb::FloatGrid::Accessor access = grid->getAccessor();
    const int64_t nx = g.dims[0], ny = g.dims[1], nz = g.dims[2];
    for (int64_t k = 0; k < nz; progress.report(band, uint64_t(++k), uint64_t(nz)))
        for (int64_t j = 0; j < ny; ++j)
            for (int64_t i = 0; i < nx; ++i) {
                const float value = field.values[size_t(i + nx * (j + ny * k))];
                if (std::abs(value) < background)
                    access.setValue(openvdb::Coord(int(i), int(j), int(k)), value);
            }
    openvdb::tools::signedFloodFill(grid->tree());

    // Phase 3: the file.
    progress.report(file, 0, 1);
    write_vdb_file(path, grid, [&] { progress.finish(); });
}

}  // namespace oclvox::detail
