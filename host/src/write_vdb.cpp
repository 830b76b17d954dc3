// OpenVDB occupancy writer: a BoolGrid named "occupancy", voxel (i, j, k) at index (i, j, k),
// value true and active where the voxel is set, background false; placed in world units by the
// shared voxel-centre transform (vdb_format.hpp) with our grid recorded as metadata.
//
// Why BoolGrid rather than MaskGrid: both hold one active bit per voxel in 8^3 leaves and cost
// about the same, but BoolGrid is the type OpenVDB's Python module, Houdini and Blender read,
// while MaskGrid is missing from pyopenvdb. The grid class is "unknown": it is neither a level
// set nor a fog volume.
//
// Why the tree is serialized here rather than by OpenVDB: building OpenVDB's tree (a heap
// allocation per leaf, freed again after) and its serial writer, several small writes per leaf,
// cost more than the voxelization they write (bunny00 at 4096^3: 0.8 s against 0.5 s). The file
// holds nothing but the leaves' bit masks, their origins and the internal nodes' masks, all of
// which follow from the bricks. So the leaves are made straight from the bricks on all cores,
// put in OpenVDB's order, and written in large pieces, the tree laid out exactly as OpenVDB's
// writer lays out the same tree once pruned (full leaves and full internal nodes as active tiles;
// the tests compare the bytes with OpenVDB's own file). OpenVDB itself writes everything before
// the tree (header, grid descriptor, metadata, transform) from a grid with an empty tree; the
// statistics metadata it would add from the tree are worked out here.
//
// The layout (OpenVDB file format 224, tree Root -> Internal<5> -> Internal<4> -> Leaf<bool, 3>,
// compression "active mask" only):
//   topology: int32 1 (buffer count); root: bool background, uint32 tiles, uint32 children, each
//     tile (int32 x, y, z, bool value, bool active), each child (int32 x, y, z, its topology);
//     internal node: child mask, value mask, one byte 0 (inactive values are all background)
//     and a byte 1 per active tile, then its children's topology; leaf: its value mask.
//   buffers: each leaf in order: value mask, int32 x, y, z origin, value bits.
// Children come in offset order (x slowest, z fastest) and root entries in coordinate order.

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <climits>
#include <cstring>
#include <sstream>
#include <unordered_map>

#include "atomic_file.hpp"
#include "bit_count.hpp"
#include "block_writer.hpp"
#include "brick_layout.hpp"
#include "vdb_format.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

using Tree = openvdb::BoolTree;
using Root = Tree::RootNodeType;
using Upper = Root::ChildNodeType;   // Internal<5>: 32^3 children of 128^3 voxels
using Lower = Upper::ChildNodeType;  // Internal<4>: 16^3 leaves
using Leaf = Tree::LeafNodeType;     // 8^3 voxels
static_assert(Leaf::LOG2DIM == 3 && Lower::LOG2DIM == 4 && Upper::LOG2DIM == 5,
              "the layout below is OpenVDB's standard 5-4-3 tree");

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

// Sorting keys sort leaves as OpenVDB writes them: by root entry (its coordinates, x first),
// then offset in the upper node, then offset in the lower node. Grid indices are below 2^20, so
// a root entry's coordinates (index >> 12) fit 8 bits each.
constexpr int kLowerBits = 12, kUpperBits = 15;
uint64_t leaf_key(int64_t x, int64_t y, int64_t z) {
    const uint64_t root = uint64_t(x >> 12) << 16 | uint64_t(y >> 12) << 8 | uint64_t(z >> 12);
    const uint64_t upper =
        uint64_t(x >> 7 & 31) << 10 | uint64_t(y >> 7 & 31) << 5 | uint64_t(z >> 7 & 31);
    const uint64_t lower =
        uint64_t(x >> 3 & 15) << 8 | uint64_t(y >> 3 & 15) << 4 | uint64_t(z >> 3 & 15);
    return root << (kUpperBits + kLowerBits) | upper << kLowerBits | lower;
}
std::array<int32_t, 3> leaf_origin(uint64_t key) {
    const uint64_t root = key >> (kUpperBits + kLowerBits), upper = key >> kLowerBits & 32767,
                   lower = key & 4095;
    return {int32_t((root >> 16) << 12 | (upper >> 10) << 7 | (lower >> 8) << 3),
            int32_t((root >> 8 & 255) << 12 | (upper >> 5 & 31) << 7 | (lower >> 4 & 15) << 3),
            int32_t((root & 255) << 12 | (upper & 31) << 7 | (lower & 15) << 3)};
}

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

// The tree above the leaves, as the pruned OpenVDB tree has it: a node whose every entry is an
// active tile (every leaf, or every lower node, full) is itself an active tile.
struct LowerNode {
    uint64_t key;       // of its leaves, less their lower offset
    size_t first, end;  // its leaves in the sorted list
    size_t full_leaves = 0;
    bool full() const { return full_leaves == size_t(Lower::NUM_VALUES); }
};
struct UpperNode {
    uint64_t key;       // its root entry
    size_t first, end;  // its lower nodes
    size_t full_lowers = 0;
    bool full() const { return full_lowers == size_t(Upper::NUM_VALUES); }
};

struct TreeShape {
    std::vector<LowerNode> lowers;
    std::vector<UpperNode> uppers;
};

TreeShape tree_shape(const std::vector<LeafBits>& leaves) {
    TreeShape shape;
    for (size_t i = 0; i < leaves.size(); ++i) {
        const uint64_t lower_key = leaves[i].key >> kLowerBits;
        if (shape.lowers.empty() || shape.lowers.back().key != lower_key)
            shape.lowers.push_back({lower_key, i, i});
        LowerNode& lower = shape.lowers.back();
        lower.end = i + 1;
        lower.full_leaves += is_full(leaves[i]);
    }
    for (size_t i = 0; i < shape.lowers.size(); ++i) {
        const uint64_t upper_key = shape.lowers[i].key >> kUpperBits;
        if (shape.uppers.empty() || shape.uppers.back().key != upper_key)
            shape.uppers.push_back({upper_key, i, i});
        UpperNode& upper = shape.uppers.back();
        upper.end = i + 1;
        upper.full_lowers += shape.lowers[i].full();
    }
    return shape;
}

// The bytes of `value` as they lie in memory, as OpenVDB writes its masks and coordinates (its
// files are little-endian, as is every host it supports).
template <class T>
void put_bytes(BlockWriter& sink, const T& value) {
    sink.bytes(reinterpret_cast<const char*>(&value), sizeof(T));
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
    auto put_origin = [&](uint64_t upper_key) {
        const auto o = leaf_origin(upper_key << (kUpperBits + kLowerBits));
        put_bytes(sink, o);
    };
    for (const UpperNode& upper : shape.uppers)
        if (upper.full()) {
            put_origin(upper.key);
            sink.little_endian(uint8_t(1));  // value
            sink.little_endian(uint8_t(1));  // active
        }
    std::vector<uint32_t> children, tiles;
    for (const UpperNode& upper : shape.uppers) {
        if (upper.full()) continue;
        put_origin(upper.key);
        children.clear();
        tiles.clear();
        for (size_t l = upper.first; l < upper.end; ++l)
            (shape.lowers[l].full() ? tiles : children)
                .push_back(uint32_t(shape.lowers[l].key & 32767));
        put_node_masks<Upper::NUM_VALUES>(sink, children, tiles);
        for (size_t l = upper.first; l < upper.end; ++l) {
            const LowerNode& lower = shape.lowers[l];
            if (lower.full()) continue;
            children.clear();
            tiles.clear();
            for (size_t i = lower.first; i < lower.end; ++i)
                (is_full(leaves[i]) ? tiles : children).push_back(uint32_t(leaves[i].key & 4095));
            put_node_masks<Lower::NUM_VALUES>(sink, children, tiles);
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

// The statistics metadata OpenVDB's writer adds (GridBase::addStatsMetadata): the active
// voxels' box and count, and the tree's memory as tools::memUsage counts it.
void add_stats_metadata(openvdb::GridBase& vdb, const std::vector<LeafBits>& leaves,
                        const TreeShape& shape) {
    openvdb::CoordBBox box;  // empty
    uint64_t active = 0;
    for (const LeafBits& leaf : leaves) {
        const auto o = leaf_origin(leaf.key);
        uint64_t yz = 0;
        int x_lo = 8, x_hi = -1;
        for (int x = 0; x < 8; ++x) {
            if (!leaf.words[x]) continue;
            x_lo = std::min(x_lo, x);
            x_hi = x;
            yz |= leaf.words[x];
            active += uint64_t(popcount64(leaf.words[x]));
        }
        int y_lo = 8, y_hi = -1;
        uint64_t z_bits = 0;
        for (int y = 0; y < 8; ++y) {
            const uint64_t row = yz >> (8 * y) & 255;
            if (!row) continue;
            y_lo = std::min(y_lo, y);
            y_hi = y;
            z_bits |= row;
        }
        const int z_lo = __builtin_ctzll(z_bits), z_hi = 63 - __builtin_clzll(z_bits);
        box.expand(openvdb::Coord(o[0] + x_lo, o[1] + y_lo, o[2] + z_lo));
        box.expand(openvdb::Coord(o[0] + x_hi, o[1] + y_hi, o[2] + z_hi));
    }
    // Node sizes as tools::memUsage counts them: the tree and root objects, each internal node's
    // table and masks and origin, each leaf object.
    auto internal_bytes = [](auto node) {
        using Node = decltype(node);
        return uint64_t(Node::NUM_VALUES * sizeof(typename Node::UnionType) +
                        typename Node::NodeMaskType().memUsage() * 2 + sizeof(openvdb::Coord));
    };
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
    const uint64_t memory = sizeof(Tree) + sizeof(Root) + uppers * internal_bytes(Upper()) +
                            lowers * internal_bytes(Lower()) + kept_leaves * sizeof(Leaf);
    vdb.insertMeta(openvdb::GridBase::META_FILE_BBOX_MIN,
                   openvdb::Vec3IMetadata(box.min().asVec3i()));
    vdb.insertMeta(openvdb::GridBase::META_FILE_BBOX_MAX,
                   openvdb::Vec3IMetadata(box.max().asVec3i()));
    vdb.insertMeta(openvdb::GridBase::META_FILE_MEM_BYTES,
                   openvdb::Int64Metadata(openvdb::Int64(memory)));
    vdb.insertMeta(openvdb::GridBase::META_FILE_VOXEL_COUNT,
                   openvdb::Int64Metadata(openvdb::Int64(active)));
}

}  // namespace

void write_vdb(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress) {
    openvdb::initialize();
    const size_t gather = progress.add(1), file = progress.add(2);

    // Phase 1: the leaves from the bricks, in OpenVDB's order, and the nodes above them.
    progress.report(gather, 0, 1);
    const std::vector<LeafBits> leaves = sorted_leaves(voxels);
    const TreeShape shape = tree_shape(leaves);
    progress.report(gather, 1, 1);

    // Phase 2: what precedes the tree, as OpenVDB writes it for this grid with an empty tree:
    // the file header, the grid descriptor, the compression flags, the metadata (ours and the
    // statistics of the real tree), the transform. The empty tree's own topology (buffer count,
    // background, no tiles, no children) is the 13 bytes that end it.
    const uint32_t compression = openvdb::io::COMPRESS_ACTIVE_MASK;
    openvdb::BoolGrid::Ptr vdb = openvdb::BoolGrid::create(false);
    place_vdb_grid(*vdb, voxels.grid(), "occupancy", openvdb::GRID_UNKNOWN);
    add_stats_metadata(*vdb, leaves, shape);
    vdb->insertMeta(openvdb::GridBase::META_FILE_COMPRESSION,
                    openvdb::StringMetadata(openvdb::io::compressionToString(compression)));
    std::ostringstream head;
    {
        openvdb::io::Stream stream(head);
        stream.setCompression(compression);
        stream.setGridStatsMetadataEnabled(false);  // added above, from the real tree
        stream.write(openvdb::GridCPtrVec{vdb});
    }
    std::string prefix = std::move(head).str();
    static const char kEmptyTree[13] = {1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    if (prefix.size() < sizeof(kEmptyTree) ||
        std::memcmp(prefix.data() + prefix.size() - sizeof(kEmptyTree), kEmptyTree,
                    sizeof(kEmptyTree)) != 0)
        throw OutputError("writing '" + path +
                          "': this OpenVDB library does not end a grid with the empty tree's "
                          "topology as file format 224 does");
    prefix.resize(prefix.size() - sizeof(kEmptyTree));

    // Phase 3: the file: the prefix, the tree's topology, its leaves' buffers.
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter sink(out);
        sink.bytes(prefix.data(), prefix.size());
        put_topology(sink, leaves, shape);
        put_buffers(sink, leaves, shape,
                    [&](size_t done) { progress.report(file, done, leaves.size()); });
        sink.flush();
        progress.finish();
    });
}

}  // namespace oclvox::detail
