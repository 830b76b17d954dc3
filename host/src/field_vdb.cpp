// OpenVDB level-set files read into sparse fields: a level set's leaves and tiles, sample (i, j, k)
// of the field at OpenVDB index (i, j, k) for our own files (write_level_set_vdb.cpp writes them
// without OpenVDB), placed by their transform for any other.
#include "field_vdb.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "host_memory.hpp"
#include "number_text.hpp"
#include "openvdb_headers.hpp"
#include "writers.hpp"

// Only here: rebuilding pulls in OpenVDB's mesher and mesh-to-volume (see openvdb_headers.hpp for
// the visibility).
#pragma GCC visibility push(default)
#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/LevelSetRebuild.h>
#pragma GCC visibility pop

namespace oclvox::detail {

namespace {

// OpenVDB's index space has its sample (i, j, k) at index point (i, j, k); ours has voxel
// (i, j, k) centred at origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size. So the transform scales
// by voxel_size and translates to vdb_index_origin (writers.hpp), as every .vdb we write does:
// the same integer (i, j, k) addresses the same voxel in both, and world positions agree.
openvdb::math::Transform::Ptr voxel_centre_transform(const Grid& grid) {
    openvdb::math::Transform::Ptr transform =
        openvdb::math::Transform::createLinearTransform(grid.voxel_size);
    const std::array<double, 3> centre = vdb_index_origin(grid);
    transform->postTranslate(openvdb::Vec3d(centre[0], centre[1], centre[2]));
    return transform;
}

[[noreturn]] void bad_vdb(const std::string& path, const std::string& why) {
    throw InputError("cannot read field " + path + ": " + why);
}

// The level set to read: the grid named "sdf" (write_field's), else the only float level set.
openvdb::FloatGrid::ConstPtr pick_level_set(const std::string& path,
                                            const openvdb::GridPtrVec& grids) {
    std::vector<openvdb::FloatGrid::ConstPtr> level_sets;
    for (const openvdb::GridBase::Ptr& grid : grids) {
        auto floats = openvdb::gridConstPtrCast<openvdb::FloatGrid>(grid);
        if (!floats) continue;
        if (floats->getName() == "sdf") return floats;
        if (floats->getGridClass() == openvdb::GRID_LEVEL_SET) level_sets.push_back(floats);
    }
    if (level_sets.size() != 1)
        bad_vdb(path, level_sets.empty()
                          ? "it holds no float level set (a FloatGrid named \"sdf\" or of class "
                            "level set)"
                          : "it holds " + std::to_string(level_sets.size()) +
                                " float level sets and none named \"sdf\"; which one is meant "
                                "is unclear");
    return level_sets[0];
}

// The grid of the field and the OpenVDB index of its voxel (0, 0, 0). Our own files say their grid
// in metadata; for others it is the box of the leaves and inside tiles, one voxel wider (so the
// border is outside), its low corner on a multiple of the leaf size (so leaves stay leaves).
Grid field_grid(const std::string& path, const openvdb::FloatGrid& vdb,
                const openvdb::CoordBBox& used, openvdb::Coord& shift, const Grid* lattice) {
    const openvdb::math::Transform& transform = vdb.transform();
    const openvdb::Vec3d zero = transform.indexToWorld(openvdb::Vec3d(0, 0, 0));
    const double voxel = transform.voxelSize()[0];
    for (int a = 0; a < 3; ++a) {
        openvdb::Vec3d step(0, 0, 0);
        step[a] = 1;
        const openvdb::Vec3d d = transform.indexToWorld(step) - zero;
        for (int b = 0; b < 3; ++b)
            if (!transform.isLinear() || !(std::abs(d[b] - (a == b ? voxel : 0.0)) <= 1e-9 * voxel))
                bad_vdb(path,
                        "its transform is not a uniform scale and translation (axis-aligned "
                        "cubic voxels), which a field's grid needs");
    }
    if (!(voxel > 0) || !std::isfinite(voxel) || !std::isfinite(zero[0]) ||
        !std::isfinite(zero[1]) || !std::isfinite(zero[2]))
        bad_vdb(path, "its transform is not finite");

    Grid grid;
    grid.voxel_size = voxel;
    const auto dims = vdb.getMetadata<openvdb::Vec3IMetadata>("oclvox_dims");
    if (dims) {
        shift = openvdb::Coord(0, 0, 0);
        for (int a = 0; a < 3; ++a) grid.dims[a] = dims->value()[a];
    } else {
        if (used.empty()) bad_vdb(path, "its level set has no leaves, so it has no surface");
        const int leaf = SparseField::kLeaf;
        for (int a = 0; a < 3; ++a) {
            const int64_t lo = int64_t(used.min()[a]) - 1, hi = int64_t(used.max()[a]) + 2;
            const int64_t aligned = lo >= 0 ? lo / leaf * leaf : -((-lo + leaf - 1) / leaf) * leaf;
            shift[a] = int(aligned);
            grid.dims[a] = hi - aligned;
        }
    }
    // Sample (i, j, k) sits at index (i, j, k) + shift, i.e. at world zero + (index) * voxel,
    // which is the centre origin + (i + 0.5) * voxel of our voxel (i, j, k). Our own files keep
    // the exact origin and voxel size, which the transform gives only up to rounding.
    for (int a = 0; a < 3; ++a) grid.origin[a] = zero[a] + (double(shift[a]) - 0.5) * voxel;
    const auto origin = vdb.getMetadata<openvdb::Vec3DMetadata>("oclvox_origin");
    const auto size = vdb.getMetadata<openvdb::DoubleMetadata>("oclvox_voxel_size");
    if (dims && origin && size) {
        for (int a = 0; a < 3; ++a)
            if (!(std::abs(origin->value()[a] - grid.origin[a]) <=
                  1e-9 * (std::abs(grid.origin[a]) + voxel)) ||
                !(std::abs(size->value() - voxel) <= 1e-9 * voxel))
                bad_vdb(path, "its oclvox metadata does not match its transform");
        for (int a = 0; a < 3; ++a) grid.origin[a] = origin->value()[a];
        grid.voxel_size = size->value();
    }
    if (lattice) {  // rebuilt on it: its exact voxel size and voxel corners
        for (int a = 0; a < 3; ++a)
            grid.origin[a] = lattice->origin[a] + std::round((grid.origin[a] - lattice->origin[a]) /
                                                             lattice->voxel_size) *
                                                      lattice->voxel_size;
        grid.voxel_size = lattice->voxel_size;
    }
    try {
        validate_grid(grid);
    } catch (const GridError& e) {
        bad_vdb(path, e.what());
    }
    return grid;
}

// The file's level set (pick_level_set), with a background a level set can have.
openvdb::FloatGrid::ConstPtr read_level_set(const std::string& path) {
    openvdb::initialize();
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path);
        file.open(false);
        grids = file.getGrids();
        file.close();
    } catch (const std::exception& e) {
        bad_vdb(path, std::string("not a readable .vdb file (") + e.what() + ")");
    }
    openvdb::FloatGrid::ConstPtr vdb = pick_level_set(path, *grids);
    const float background = vdb->background();
    if (!(background > 0) || !std::isfinite(background))
        bad_vdb(path, "its background " + std::to_string(background) +
                          " is not positive and finite, as a level set's is");
    return vdb;
}

// A level set as a sparse field; `path` names it in errors. A level set rebuilt on `lattice`
// takes its exact voxel size and voxel corners (its transform holds them up to rounding).
SparseField level_set_field(const std::string& path, const openvdb::FloatGrid& level_set,
                            const Grid* lattice = nullptr) {
    const openvdb::FloatGrid* vdb = &level_set;
    const openvdb::FloatTree& tree = vdb->tree();
    const float background = vdb->background();

    // Phase 2: what the field will hold: the leaves and the tiles below zero (inside), never an
    // active tile (a narrow band's values are all in leaves).
    openvdb::CoordBBox used;
    std::vector<openvdb::CoordBBox> inside_tiles;
    for (auto it = tree.cbeginLeaf(); it; ++it) used.expand(it->getNodeBoundingBox());
    {
        auto tile = tree.cbeginValueAll();
        tile.setMaxDepth(openvdb::FloatTree::ValueAllCIter::LEAF_DEPTH - 1);
        for (; tile; ++tile) {
            if (tile.isVoxelValue()) continue;
            if (tile.isValueOn())
                bad_vdb(path,
                        "it has active tiles; a narrow-band level set keeps its values in "
                        "leaves");
            if (!(*tile < 0)) continue;
            openvdb::CoordBBox box;
            tile.getBoundingBox(box);
            inside_tiles.push_back(box);
            used.expand(box);
        }
    }
    openvdb::Coord shift;
    const Grid grid = field_grid(path, *vdb, used, shift, lattice);
    auto to_grid = [&](const openvdb::Coord& c) {
        return std::array<int64_t, 3>{int64_t(c[0]) - shift[0], int64_t(c[1]) - shift[1],
                                      int64_t(c[2]) - shift[2]};
    };

    // Before allocating: the leaves' samples and the inside bits of the tiles within the grid.
    uint64_t inside_voxels = 0;
    for (const openvdb::CoordBBox& box : inside_tiles) {
        uint64_t volume = 1;
        const auto lo = to_grid(box.min()), hi = to_grid(box.max());
        for (int a = 0; a < 3; ++a)
            volume *= uint64_t(std::max<int64_t>(
                0, std::min(hi[a] + 1, grid.dims[a]) - std::max<int64_t>(lo[a], 0)));
        inside_voxels += volume;
    }
    try {
        check_host_memory(
            tree.leafCount() * (SparseField::kLeafSamples * sizeof(float) + 64) + inside_voxels / 8,
            default_host_budget(), "the field's leaves and inside voxels");
    } catch (const GridError& e) {
        bad_vdb(path, e.what());
    }

    // Phase 3: the leaves, in our leaf order, as samples (OpenVDB stores z fastest, we x fastest)
    // and their voxels below zero as inside voxels.
    const std::array<int64_t, 3> leaf_dims = {
        (grid.dims[0] + SparseField::kLeaf - 1) / SparseField::kLeaf,
        (grid.dims[1] + SparseField::kLeaf - 1) / SparseField::kLeaf,
        (grid.dims[2] + SparseField::kLeaf - 1) / SparseField::kLeaf};
    std::vector<std::pair<uint64_t, const openvdb::FloatTree::LeafNodeType*>> leaves;
    leaves.reserve(tree.leafCount());
    for (auto it = tree.cbeginLeaf(); it; ++it) {
        const auto o = to_grid(it->origin());
        for (int a = 0; a < 3; ++a)
            if (o[a] < 0 || o[a] >= grid.dims[a])
                bad_vdb(path, "a leaf at index (" + std::to_string(it->origin()[0]) + ", " +
                                  std::to_string(it->origin()[1]) + ", " +
                                  std::to_string(it->origin()[2]) +
                                  ") lies outside the grid its oclvox_dims metadata gives");
        const int64_t leaf = SparseField::kLeaf;
        leaves.push_back(
            {uint64_t(o[0] / leaf) +
                 uint64_t(leaf_dims[0]) *
                     (uint64_t(o[1] / leaf) + uint64_t(leaf_dims[1]) * uint64_t(o[2] / leaf)),
             it.getLeaf()});
    }
    std::sort(leaves.begin(), leaves.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });

    // The inside voxels: the tiles below zero, then each leaf's voxels below zero.
    constexpr int64_t kBrick = 32;
    SparseVoxels inside(grid, kBrick);
    for (const openvdb::CoordBBox& box : inside_tiles) {
        const auto lo = to_grid(box.min()), last = to_grid(box.max());
        inside.set_box(lo, {last[0] + 1, last[1] + 1, last[2] + 1});
    }
    // A leaf lies in one brick (bricks are whole leaves), so each brick's leaves are gathered
    // into its words and merged once.
    const std::array<int64_t, 3> bricks = inside.brick_dims();
    std::vector<std::pair<uint64_t, size_t>> by_brick;  // (brick, position in leaves)
    by_brick.reserve(leaves.size());
    for (size_t l = 0; l < leaves.size(); ++l) {
        const auto o = to_grid(leaves[l].second->origin());
        by_brick.push_back(
            {uint64_t(o[0] / kBrick) +
                 uint64_t(bricks[0]) *
                     (uint64_t(o[1] / kBrick) + uint64_t(bricks[1]) * uint64_t(o[2] / kBrick)),
             l});
    }
    std::sort(by_brick.begin(), by_brick.end());
    std::vector<uint64_t> words(inside.blocks_per_brick());
    const int64_t per_axis = inside.blocks_per_brick_axis();
    for (size_t i = 0; i < by_brick.size();) {
        const uint64_t brick = by_brick[i].first;
        std::fill(words.begin(), words.end(), 0);
        for (; i < by_brick.size() && by_brick[i].first == brick; ++i) {
            const openvdb::FloatTree::LeafNodeType& leaf = *leaves[by_brick[i].second].second;
            const float* values = leaf.buffer().data();  // z fastest
            const auto o = to_grid(leaf.origin());
            // The leaf's voxels within the grid, and where it lies in its brick.
            const int64_t nx = std::min<int64_t>(SparseField::kLeaf, grid.dims[0] - o[0]);
            const int64_t ny = std::min<int64_t>(SparseField::kLeaf, grid.dims[1] - o[1]);
            const int64_t nz = std::min<int64_t>(SparseField::kLeaf, grid.dims[2] - o[2]);
            const int64_t bx = o[0] % kBrick, by = o[1] % kBrick, bz = o[2] % kBrick;
            for (int64_t x = 0; x < nx; ++x)
                for (int64_t y = 0; y < ny; ++y)
                    for (int64_t z = 0; z < nz; ++z) {
                        if (!(values[(x << 6) | (y << 3) | z] < 0)) continue;
                        const int64_t lx = bx + x, ly = by + y, lz = bz + z;
                        words[size_t(lx / 4 + per_axis * (ly / 4 + per_axis * (lz / 4)))] |=
                            uint64_t(1) << (lx % 4 + 4 * (ly % 4 + 4 * (lz % 4)));
                    }
        }
        inside.merge_brick(brick, words.data());
    }

    // Phase 4: the field. Its samples are transposed a chunk of leaves at a time on every core and
    // appended in order; the first leaf with a sample that is not finite, in leaf order, is the
    // one named. Samples are read from the leaf's buffer (getValue checks for a delayed load at
    // every sample: read so, one leaf after another, they were two fifths of reading a 512^3 band).
    SparseField field(grid, double(background) / grid.voxel_size, std::move(inside));
    field.reserve_leaves(leaves.size());
    constexpr size_t kChunkLeaves = 4096;  // 8 MiB of samples
    std::vector<float> chunk(std::min(kChunkLeaves, leaves.size()) * SparseField::kLeafSamples);
    std::vector<char> finite(std::min(kChunkLeaves, leaves.size()));
    for (size_t first = 0; first < leaves.size(); first += kChunkLeaves) {
        const size_t count = std::min(kChunkLeaves, leaves.size() - first);
        tbb::parallel_for(size_t(0), count, [&](size_t i) {
            const float* values = leaves[first + i].second->buffer().data();  // z fastest
            float* samples = &chunk[i * SparseField::kLeafSamples];           // x fastest
            bool all_finite = true;
            for (int x = 0; x < SparseField::kLeaf; ++x)
                for (int y = 0; y < SparseField::kLeaf; ++y)
                    for (int z = 0; z < SparseField::kLeaf; ++z) {
                        const float value = values[(x << 6) | (y << 3) | z];
                        all_finite = all_finite && std::isfinite(value);
                        samples[x + SparseField::kLeaf * (y + SparseField::kLeaf * z)] = value;
                    }
            finite[i] = all_finite;
        });
        for (size_t i = 0; i < count; ++i) {
            if (!finite[i]) {
                const openvdb::Coord& o = leaves[first + i].second->origin();
                bad_vdb(path, "a sample of the leaf at index (" + std::to_string(o[0]) + ", " +
                                  std::to_string(o[1]) + ", " + std::to_string(o[2]) +
                                  ") is not finite");
            }
            field.append_leaf(leaves[first + i].first, &chunk[i * SparseField::kLeafSamples]);
        }
    }
    return field;
}

}  // namespace

SparseField read_field_vdb(const std::string& path) {
    return level_set_field(path, *read_level_set(path));
}

SparseField read_field_vdb(const std::string& path, const Grid& lattice, double band_voxels) {
    validate_grid(lattice);
    const float background = float(band_voxels * lattice.voxel_size);
    if (!(background > 0) || !std::isfinite(background))
        throw GridError("a level set's band must be finite and positive, got " +
                        detail::number_text(band_voxels) + " voxels");
    const openvdb::FloatGrid::ConstPtr vdb = read_level_set(path);
    // On the lattice already: the same voxel size, and index 0's centre whole voxels from the
    // lattice's voxel (0, 0, 0) (the tolerances of csg's lattice test).
    const openvdb::Vec3d zero = vdb->transform().indexToWorld(openvdb::Vec3d(0, 0, 0));
    bool on_lattice =
        vdb->transform().isLinear() &&
        std::abs(vdb->voxelSize()[0] - lattice.voxel_size) <= 1e-9 * lattice.voxel_size &&
        vdb->background() == background;
    for (int a = 0; a < 3 && on_lattice; ++a) {
        const double voxels =
            (zero[a] - (lattice.origin[a] + 0.5 * lattice.voxel_size)) / lattice.voxel_size;
        on_lattice = std::abs(voxels - std::round(voxels)) <= 1e-6;
    }
    if (on_lattice) return level_set_field(path, *vdb);
    // The rebuild polygonizes the surface and signs the new band by flooding from outside, which
    // needs a closed surface: one its grid's box cuts (inside samples on the box's faces, as a
    // field computed on too small a grid has) would come back with its inside lost.
    const uint64_t cut = border_samples_inside(level_set_field(path, *vdb));
    if (cut > 0)
        bad_vdb(path, "its surface is cut by its grid's box (" + std::to_string(cut) +
                          " samples on the box's faces are inside), so it cannot be rebuilt on "
                          "another lattice: compute it on a grid that holds the whole surface");

    // Rebuilt on the lattice's transform with its band (levelSetRebuild also when the transform
    // is the file's, where resampleToMatch would copy the tree and keep the file's band).
    openvdb::FloatGrid::Ptr rebuilt;
    try {
        const float half_width = float(band_voxels);
        rebuilt = openvdb::tools::levelSetRebuild(*vdb, 0.0f, half_width, half_width,
                                                  voxel_centre_transform(lattice).get());
        // The rebuild's background is band * voxel size rounded its own way; the band's
        // background, as the lattice's fields hold it, is what combining them compares.
        openvdb::tools::changeLevelSetBackground(rebuilt->tree(), background);
    } catch (const std::exception& e) {
        bad_vdb(path, std::string("its level set could not be rebuilt on the lattice (") +
                          e.what() + ")");
    }
    return level_set_field(path, *rebuilt, &lattice);
}

}  // namespace oclvox::detail
