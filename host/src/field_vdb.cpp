// OpenVDB level-set output: sample (i, j, k) of the field at OpenVDB index (i, j, k), placed by
// the shared voxel-centre transform (vdb_format.hpp). Dense and sparse fields go through the same
// writer, which takes the field a leaf of OpenVDB's tree (8x8x8 voxels) at a time.
#include "field_vdb.hpp"

#include <openvdb/tools/SignedFloodFill.h>

#include "vdb_format.hpp"

namespace oclvox::detail {

namespace {

constexpr int kLeaf = SparseField::kLeaf;

// One leaf of the field: its minimum voxel and its 8x8x8 samples, x fastest (those beyond the
// grid are never read).
using LeafVisit = std::function<void(const std::array<int64_t, 3>& origin, const float* samples)>;

// The level set of the leaves for_each_leaf(visit) visits (every leaf that may hold a sample
// within the band; `leaves` of them, for progress).
void write_level_set(const std::string& path, const Grid& g, double band_voxels,
                     ProgressPhases& progress, uint64_t leaves,
                     const std::function<void(const LeafVisit&)>& for_each_leaf) {
    openvdb::initialize();
    const float background = float(band_voxels * g.voxel_size);

    // Phase 1: grid, transform and metadata.
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(background);
    place_vdb_grid(*grid, g, "sdf", openvdb::GRID_LEVEL_SET);
    grid->insertMeta("oclvox_band_voxels", openvdb::DoubleMetadata(band_voxels));

    // Phase 2: the narrow band as active voxels, leaf by leaf. The rest stays background, and the
    // signed flood fill then gives the inactive regions inside the surface the background's
    // negative, as a level set's tiles must have.
    // The band, then the flood fill and the file (no progress of their own, estimated at about
    // the band's cost together).
    const size_t band = progress.add(2), file = progress.add(1);
    openvdb::FloatTree& tree = grid->tree();
    uint64_t visited = 0;
    for_each_leaf([&](const std::array<int64_t, 3>& origin, const float* samples) {
        const int64_t nx = std::min<int64_t>(kLeaf, g.dims[0] - origin[0]);
        const int64_t ny = std::min<int64_t>(kLeaf, g.dims[1] - origin[1]);
        const int64_t nz = std::min<int64_t>(kLeaf, g.dims[2] - origin[2]);
        openvdb::FloatTree::LeafNodeType* leaf = nullptr;
        for (int64_t z = 0; z < nz; ++z)
            for (int64_t y = 0; y < ny; ++y)
                for (int64_t x = 0; x < nx; ++x) {
                    const float value = samples[x + kLeaf * (y + kLeaf * z)];
                    if (!(std::abs(value) < background)) continue;
                    if (!leaf)
                        leaf = tree.touchLeaf(
                            openvdb::Coord(int(origin[0]), int(origin[1]), int(origin[2])));
                    leaf->setValueOn(
                        openvdb::Coord(int(origin[0] + x), int(origin[1] + y), int(origin[2] + z)),
                        value);
                }
        progress.report(band, ++visited, leaves);
    });
    openvdb::tools::signedFloodFill(tree);

    // Phase 3: the file.
    progress.report(file, 0, 1);
    write_vdb_file(path, grid, [&] { progress.finish(); });
}

}  // namespace

void write_field_vdb(const std::string& path, const ScalarField& field, double band_voxels,
                     ProgressPhases& progress) {
    // Every leaf of the grid, gathered from the dense samples a row at a time.
    const Grid& g = field.grid;
    const auto& d = g.dims;
    const uint64_t leaves = uint64_t((d[0] + kLeaf - 1) / kLeaf) *
                            uint64_t((d[1] + kLeaf - 1) / kLeaf) *
                            uint64_t((d[2] + kLeaf - 1) / kLeaf);
    write_level_set(path, g, band_voxels, progress, leaves, [&](const LeafVisit& visit) {
        float samples[SparseField::kLeafSamples];
        for (int64_t z = 0; z < d[2]; z += kLeaf)
            for (int64_t y = 0; y < d[1]; y += kLeaf)
                for (int64_t x = 0; x < d[0]; x += kLeaf) {
                    const int64_t row = std::min<int64_t>(kLeaf, d[0] - x);
                    for (int64_t k = z; k < std::min(z + kLeaf, d[2]); ++k)
                        for (int64_t j = y; j < std::min(y + kLeaf, d[1]); ++j)
                            std::copy_n(&field.values[size_t(x + d[0] * (j + d[1] * k))], row,
                                        &samples[kLeaf * ((j - y) + kLeaf * (k - z))]);
                    visit({x, y, z}, samples);
                }
    });
}

void write_field_vdb(const std::string& path, const SparseField& field, ProgressPhases& progress) {
    // The stored leaves only: every sample outside them is the background.
    write_level_set(path, field.grid(), field.band_voxels(), progress, field.leaf_count(),
                    [&](const LeafVisit& visit) {
                        for (size_t l = 0; l < field.leaf_count(); ++l)
                            visit(field.leaf_origin(field.leaf_indices()[l]),
                                  field.leaf_samples(l));
                    });
}

}  // namespace oclvox::detail
