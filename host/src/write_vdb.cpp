// OpenVDB occupancy writer: a BoolGrid named "occupancy", voxel (i, j, k) at index (i, j, k),
// value true and active where the voxel is set, background false; placed in world units by a
// transform that puts index (i, j, k) at our voxel's centre, with our grid recorded as metadata.
//
// Why BoolGrid rather than MaskGrid: both hold one active bit per voxel in 8^3 leaves and cost
// about the same, but BoolGrid is the type OpenVDB's Python module, Houdini and Blender read,
// while MaskGrid is missing from pyopenvdb. The grid class is "unknown": it is neither a level
// set nor a fog volume.
//
// Why the file is serialized here rather than by OpenVDB: building OpenVDB's tree (a heap
// allocation per leaf, freed again after) and its serial writer, several small writes per leaf,
// cost more than the voxelization they write (bunny00 at 4096^3: 0.8 s against 0.5 s), and
// loading OpenVDB at all (the module liboclvox_vdb, vdb_module.hpp) costs ~30 ms, more than a
// 1024^3 voxelization of buildings. The file holds nothing but a fixed header, a few metadata
// values, the transform, the leaves' bit masks, their origins and the internal nodes' masks, all
// of which follow from the grid and the bricks. So the leaves are made straight from the bricks on
// all cores, put in OpenVDB's order, and written in large pieces, laid out exactly as OpenVDB's
// io::Stream lays out the same grid once pruned (full leaves and full internal nodes as active
// tiles); the tests compare the bytes with OpenVDB's own file, and read it back through OpenVDB's
// C++ and Python APIs. Level sets are written the same way (write_level_set_vdb.cpp), on the
// shared layout of vdb_stream.cpp.
//
// The layout (OpenVDB file format 224 as OpenVDB 10.0 writes it to a stream, one grid, tree
// Root -> Internal<5> -> Internal<4> -> Leaf<bool, 3>, compression "active mask" only; integers
// little-endian, a string is its int32 length and its characters):
//   header: int64 magic, uint32 file version, uint32 library major and minor version, uint8 0
//     (no grid offsets: a stream), 36 characters of a random UUID, int32 0 (file metadata).
//   grid: int32 1 (grid count); descriptor: name, tree type, "" (no instance parent), three int64
//     0 (offsets, unknown to a stream); uint32 compression flags; metadata: int32 count, each
//     entry (in name order) its name, type name, int32 size, value; transform: its map's type
//     name, then translation, scale, voxel size, 1 / scale, its square, half of it (Vec3d each).
//   topology: int32 1 (buffer count); root: bool background, uint32 tiles, uint32 children, each
//     tile (int32 x, y, z, bool value, bool active), each child (int32 x, y, z, its topology);
//     internal node: child mask, value mask, one byte 0 (inactive values are all background)
//     and a byte 1 per active tile, then its children's topology; leaf: its value mask.
//   buffers: each leaf in order: value mask, int32 x, y, z origin, value bits.
// Children come in offset order (x slowest, z fastest) and root entries in coordinate order.

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <unordered_map>

#include "atomic_file.hpp"
#include "brick_layout.hpp"
#include "vdb_stream.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

using namespace vdb_stream;

// A bool leaf object's bytes as tools::memUsage counts them (see vdb_stream.hpp).
constexpr uint64_t kLeafBytes = 144;

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

// A leaf: its place in OpenVDB's order and its value mask. A leaf's offsets run z fastest,
// (x & 7) << 6 | (y & 7) << 3 | (z & 7): word x & 7 holds an 8x8 square of (y, z), bit
// (y & 7) * 8 + (z & 7).
struct LeafBits {
    uint64_t key;
    uint64_t words[8];
};

// ORs block `mask` (at voxel `o`, 4-aligned) into its leaf's words: the block is a 4x4 corner of
// four of them.
void add_block(uint64_t* words, const std::array<int64_t, 3>& o, uint64_t mask) {
    const int first_word = int(o[0] & 7), shift = int(o[1] & 7) * 8 + int(o[2] & 7);
    for (int x = 0; x < 4; ++x) words[first_word + x] |= yz_square(mask >> x) << shift;
}

// Every leaf holding a set voxel, in OpenVDB's order, each once.
std::vector<LeafBits> sorted_leaves(const SparseVoxels& voxels) {
    const BrickLayout layout(voxels);
    const std::vector<uint64_t> bricks = voxels.brick_indices();
    // Bricks whose edge is a multiple of 8 hold whole leaves; other sizes share leaves between
    // bricks, which the merge after sorting joins.
    const bool whole_leaves = voxels.brick_size() % 8 == 0;
    std::vector<std::vector<LeafBits>> per_brick(bricks.size());
    tbb::parallel_for(size_t(0), bricks.size(), [&](size_t b) {
        const uint64_t index = bricks[b];
        const uint64_t* blocks_of_brick = voxels.brick_blocks(index);
        const auto corner = layout.brick_origin(index);
        const int64_t n = std::max<int64_t>(1, voxels.brick_size() / 8);  // leaves along an edge
        std::vector<uint32_t> slot(whole_leaves ? size_t(n * n * n) : 0, UINT32_MAX);
        std::unordered_map<uint64_t, uint32_t> slot_of_key;  // without whole leaves
        std::vector<LeafBits>& own = per_brick[b];
        // Blocks x fastest (their coordinates counted, not divided out: most words are zero).
        const int64_t blocks = voxels.brick_size() / SparseVoxels::kBlock;
        size_t w = 0;
        for (int64_t bz = 0; bz < blocks; ++bz)
            for (int64_t by = 0; by < blocks; ++by)
                for (int64_t bx = 0; bx < blocks; ++bx, ++w) {
                    const uint64_t mask = blocks_of_brick[w];
                    if (!mask) continue;
                    const std::array<int64_t, 3> o{corner[0] + bx * SparseVoxels::kBlock,
                                                   corner[1] + by * SparseVoxels::kBlock,
                                                   corner[2] + bz * SparseVoxels::kBlock};
                    const uint64_t key = leaf_key(o[0], o[1], o[2]);
                    uint32_t* place = whole_leaves
                                          ? &slot[size_t(bx / 2 + n * (by / 2 + n * (bz / 2)))]
                                          : &slot_of_key.try_emplace(key, UINT32_MAX).first->second;
                    if (*place == UINT32_MAX) {
                        *place = uint32_t(own.size());
                        own.push_back(LeafBits{key, {}});
                    }
                    add_block(own[*place].words, o, mask);
                }
    });

    // One list, sorted; leaves shared between bricks merged.
    std::vector<size_t> first(bricks.size() + 1, 0);
    for (size_t b = 0; b < bricks.size(); ++b) first[b + 1] = first[b] + per_brick[b].size();
    std::vector<LeafBits> leaves(first.back());
    tbb::parallel_for(size_t(0), bricks.size(), [&](size_t b) {
        std::copy(per_brick[b].begin(), per_brick[b].end(), leaves.begin() + ptrdiff_t(first[b]));
        std::vector<LeafBits>().swap(per_brick[b]);
    });
    tbb::parallel_sort(leaves.begin(), leaves.end(),
                       [](const LeafBits& a, const LeafBits& b) { return a.key < b.key; });
    if (!whole_leaves) {
        size_t kept = 0;
        for (size_t i = 0; i < leaves.size(); ++i) {
            if (kept > 0 && leaves[kept - 1].key == leaves[i].key) {
                for (int w = 0; w < 8; ++w) leaves[kept - 1].words[w] |= leaves[i].words[w];
            } else {
                leaves[kept++] = leaves[i];
            }
        }
        leaves.resize(kept);
    }
    return leaves;
}

bool is_full(const LeafBits& leaf) {
    for (const uint64_t w : leaf.words)
        if (w != ~uint64_t(0)) return false;
    return true;
}

// An internal node's topology before its children: child mask, value mask (the active tiles),
// the mask-compressed tile values: metadata 0 (every inactive value is the background), then the
// active tiles' values.
template <size_t kEntries>
void put_node_masks(BlockWriter& sink, const std::vector<uint32_t>& children,
                    const std::vector<uint32_t>& tiles) {
    std::array<uint64_t, kEntries / 64> child_mask{}, value_mask{};
    for (const uint32_t c : children) child_mask[c >> 6] |= uint64_t(1) << (c & 63);
    for (const uint32_t t : tiles) value_mask[t >> 6] |= uint64_t(1) << (t & 63);
    put_bytes(sink, child_mask);
    put_bytes(sink, value_mask);
    sink.little_endian(int8_t(0));
    for (size_t i = 0; i < tiles.size(); ++i) sink.little_endian(uint8_t(1));
}

void put_topology(BlockWriter& sink, const std::vector<LeafBits>& leaves, const TreeShape& shape) {
    sink.little_endian(int32_t(1));  // buffer count
    sink.little_endian(uint8_t(0));  // background
    uint32_t root_tiles = 0;
    for (const UpperNode& upper : shape.uppers) root_tiles += upper.full();
    sink.little_endian(root_tiles);
    sink.little_endian(uint32_t(shape.uppers.size() - root_tiles));
    for (const UpperNode& upper : shape.uppers)
        if (upper.full()) {
            put_bytes(sink, upper_origin(upper.key));
            sink.little_endian(uint8_t(1));  // value
            sink.little_endian(uint8_t(1));  // active
        }
    std::vector<uint32_t> children, tiles;
    for (const UpperNode& upper : shape.uppers) {
        if (upper.full()) continue;
        put_bytes(sink, upper_origin(upper.key));
        children.clear();
        tiles.clear();
        for (size_t l = upper.first; l < upper.end; ++l)
            (shape.lowers[l].full() ? tiles : children)
                .push_back(uint32_t(shape.lowers[l].key & 32767));
        put_node_masks<kUpperEntries>(sink, children, tiles);
        for (size_t l = upper.first; l < upper.end; ++l) {
            const LowerNode& lower = shape.lowers[l];
            if (lower.full()) continue;
            children.clear();
            tiles.clear();
            for (size_t i = lower.first; i < lower.end; ++i)
                (is_full(leaves[i]) ? tiles : children).push_back(uint32_t(leaves[i].key & 4095));
            put_node_masks<kLowerEntries>(sink, children, tiles);
            for (size_t i = lower.first; i < lower.end; ++i)
                if (!is_full(leaves[i])) put_bytes(sink, leaves[i].words);
        }
    }
}

// Each leaf OpenVDB keeps (those not pruned to a tile), in order: value mask, origin, values
// (which are the mask: set voxels are true, the rest false).
void put_buffers(BlockWriter& sink, const std::vector<LeafBits>& leaves, const TreeShape& shape,
                 const std::function<void(size_t)>& done_leaves) {
    for (const LowerNode& lower : shape.lowers) {
        for (size_t i = lower.first; i < lower.end; ++i) {
            if (is_full(leaves[i])) continue;  // a tile (so are all leaves of a full node)
            const auto o = leaf_origin(leaves[i].key);
            put_bytes(sink, leaves[i].words);
            put_bytes(sink, o);
            put_bytes(sink, leaves[i].words);
        }
        done_leaves(lower.end);
    }
}

// The statistics of the pruned tree: its active voxels (those of tiles included) and the nodes
// and leaves it keeps.
TreeStatistics tree_statistics(const std::vector<LeafBits>& leaves, const TreeShape& shape) {
    TreeStatistics stats;
    for (const LeafBits& leaf : leaves) stats.add_leaf(leaf.key, leaf.words);
    uint64_t uppers = 0, lowers = 0, kept_leaves = 0;
    for (const UpperNode& upper : shape.uppers) {
        if (upper.full()) continue;
        ++uppers;
        for (size_t l = upper.first; l < upper.end; ++l) {
            const LowerNode& lower = shape.lowers[l];
            if (lower.full()) continue;
            ++lowers;
            kept_leaves += (lower.end - lower.first) - lower.full_leaves;
        }
    }
    stats.memory = kTreeBytes + kRootBytes + uppers * kUpperBytes + lowers * kLowerBytes +
                   kept_leaves * kLeafBytes;
    return stats;
}

}  // namespace

void write_vdb(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress) {
    const size_t gather = progress.add(1), file = progress.add(2);

    // Phase 1: the leaves from the bricks, in OpenVDB's order, the nodes above them, and the
    // statistics the metadata records.
    progress.report(gather, 0, 1);
    const std::vector<LeafBits> leaves = sorted_leaves(voxels);
    const TreeShape shape = tree_shape(
        leaves.size(), [&](size_t i) { return leaves[i].key; },
        [&](size_t i) { return is_full(leaves[i]); });
    const TreeStatistics stats = tree_statistics(leaves, shape);
    progress.report(gather, 1, 1);

    // Phase 2: the file: what precedes the tree, the tree's topology, its leaves' buffers.
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter sink(out);
        put_grid_prefix(sink, voxels.grid(), {"occupancy", "Tree_bool_5_4_3", "unknown"}, stats);
        put_topology(sink, leaves, shape);
        put_buffers(sink, leaves, shape,
                    [&](size_t done) { progress.report(file, done, leaves.size()); });
        sink.flush();
        progress.finish();
    });
}

}  // namespace oclvox::detail
