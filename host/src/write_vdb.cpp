// OpenVDB occupancy writer: a BoolGrid named "occupancy", voxel (i, j, k) at index (i, j, k),
// value true and active where the voxel is set, background false; placed in world units by the
// shared voxel-centre transform (vdb_format.hpp) with our grid recorded as metadata.
//
// Why BoolGrid rather than MaskGrid: both hold one active bit per voxel in 8^3 leaves and cost
// about the same, but BoolGrid is the type OpenVDB's Python module, Houdini and Blender read,
// while MaskGrid is missing from pyopenvdb. The grid class is "unknown": it is neither a level
// set nor a fog volume.
//
// The tree is built straight from the bricks: each 4^3 block word lands in one 8^3 leaf
// (blocks are 4-aligned), and its bits are ORed into the leaf's active and value words four rows
// of 16 at a time. Bricks whose edge is a multiple of 8 hold whole leaves, so their leaves are
// built in parallel, brick by brick, a group of bricks at a time, and handed to the tree by a task
// while the next group's are built; other brick sizes share leaves between bricks and are built in
// one pass through a cached accessor. Whole leaves that end up full are then pruned to active
// tiles, so a solid interior costs a tile, not 512 bits. No dense copy of the grid is ever made.

#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <memory>

#include "brick_layout.hpp"
#include "vdb_format.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// The 16 bits x + 4y + 16z (y, z in 0..3) of a block mask shifted right by x, as bits y * 8 + z:
// their place in an OpenVDB leaf word.
uint64_t yz_square(uint64_t shifted) {
    uint64_t square = 0;
    for (int z = 0; z < 4; ++z) {
        const uint64_t column = shifted >> (16 * z);  // bits 0, 4, 8, 12 are y = 0..3
        square |= ((column & 1) | (column >> 4 & 1) << 8 | (column >> 8 & 1) << 16 |
                   (column >> 12 & 1) << 24)
                  << z;
    }
    return square;
}

using Leaf = openvdb::BoolTree::LeafNodeType;

// ORs block `mask` (at voxel `o`, 4-aligned) into its leaf's active and value words.
void add_block(Leaf& leaf, const std::array<int64_t, 3>& o, uint64_t mask) {
    uint64_t* active = &leaf.getValueMask().template getWord<uint64_t>(0);
    uint64_t* values = leaf.buffer().data();
    // A leaf's offsets run z fastest, (x & 7) << 6 | (y & 7) << 3 | (z & 7): word x & 7 holds an
    // 8x8 square of (y, z), bit (y & 7) * 8 + (z & 7). The block is a 4x4 corner of four such
    // words.
    const int first_word = int(o[0] & 7), shift = int(o[1] & 7) * 8 + int(o[2] & 7);
    for (int x = 0; x < 4; ++x) {
        const uint64_t bits = yz_square(mask >> x) << shift;
        active[first_word + x] |= bits;
        values[first_word + x] |= bits;
    }
}

}  // namespace

void write_vdb(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress) {
    openvdb::initialize();
    openvdb::BoolGrid::Ptr vdb = openvdb::BoolGrid::create(false);
    place_vdb_grid(*vdb, voxels.grid(), "occupancy", openvdb::GRID_UNKNOWN);

    // The tree and the file cost about the same; the file has no progress of its own.
    const size_t tree = progress.add(1), file = progress.add(1);

    // Phase 1: every set voxel becomes an active true voxel, block by block, a leaf word at a
    // time; the leaves of a group of bricks at once, then the next group's.
    openvdb::tree::ValueAccessor<openvdb::BoolTree> access(vdb->tree());
    const BrickLayout layout(voxels);
    const std::vector<uint64_t> bricks = voxels.brick_indices();
    const bool whole_leaves = voxels.brick_size() % 8 == 0;
    // The leaves of brick b of the group being built (only with whole leaves).
    std::vector<std::vector<std::unique_ptr<Leaf>>> leaves;
    auto build_brick = [&](size_t b, std::vector<std::unique_ptr<Leaf>>* own) {
        const uint64_t index = bricks[b];
        const uint64_t* blocks = voxels.brick_blocks(index);
        const auto corner = layout.brick_origin(index);
        const int64_t n = voxels.brick_size() / 8;              // whole leaves along a brick edge
        std::vector<Leaf*> found(own ? size_t(n * n * n) : 0);  // own leaves, x fastest
        for (size_t w = 0; w < layout.blocks_per_brick(); ++w) {
            const uint64_t mask = blocks[w];
            if (!mask) continue;
            const auto o = layout.block_origin(index, w);
            const openvdb::Coord origin{int(o[0]), int(o[1]), int(o[2])};
            if (!own) {
                add_block(*access.touchLeaf(origin), o, mask);
                continue;
            }
            Leaf*& leaf =
                found[size_t((o[0] - corner[0]) / 8 +
                             n * ((o[1] - corner[1]) / 8 + n * ((o[2] - corner[2]) / 8)))];
            if (!leaf) {
                own->push_back(std::make_unique<Leaf>(origin & ~7, false));
                leaf = own->back().get();
            }
            add_block(*leaf, o, mask);
        }
    };
    const size_t group = whole_leaves ? 256 : bricks.size();
    // Whole leaves: a task hands one group's leaves to the tree (a serial insertion) while the
    // cores build the next group's.
    std::vector<std::vector<std::unique_ptr<Leaf>>> adding;
    tbb::task_group inserting;
    for (size_t first = 0; first < bricks.size(); first += group) {
        progress.report(tree, first, bricks.size());
        const size_t end = std::min(bricks.size(), first + group);
        if (!whole_leaves) {
            for (size_t b = first; b < end; ++b) build_brick(b, nullptr);
            continue;
        }
        leaves.clear();
        leaves.resize(end - first);
        tbb::parallel_for(first, end, [&](size_t b) { build_brick(b, &leaves[b - first]); });
        inserting.wait();
        std::swap(adding, leaves);
        inserting.run([&] {
            for (auto& own : adding)
                for (auto& leaf : own) access.addLeaf(leaf.release());
        });
    }
    inserting.wait();

    // Phase 2: full leaves become tiles, then the file.
    vdb->tree().prune();
    progress.report(file, 0, 1);
    write_vdb_file(path, vdb, [&] { progress.finish(); });
}

}  // namespace oclvox::detail
