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
// C++ and Python APIs. The field writers (field_vdb.cpp) still go through OpenVDB.
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
#include <climits>
#include <cstring>
#include <random>
#include <unordered_map>

#include "atomic_file.hpp"
#include "bit_count.hpp"
#include "block_writer.hpp"
#include "brick_layout.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

// OpenVDB's standard 5-4-3 tree: a leaf holds 8^3 voxels, a lower node 16^3 leaves, an upper
// node 32^3 lower nodes (4096^3 voxels).
constexpr size_t kLowerEntries = size_t(1) << 12, kUpperEntries = size_t(1) << 15;

// The file format this writer lays out, and the library whose writer it follows.
constexpr uint32_t kFileVersion = 224, kLibraryMajor = 10, kLibraryMinor = 0;
constexpr uint32_t kCompressActiveMask = 0x2;  // io::COMPRESS_ACTIVE_MASK

// The bytes of a BoolTree's parts as tools::memUsage counts them (OpenVDB 10 on a 64-bit host),
// for the "file_mem_bytes" metadata: the tree and root objects, each internal node's table of
// 8-byte entries, its two masks and its origin, each leaf object. The byte-for-byte test against
// OpenVDB's writer checks them.
constexpr uint64_t kTreeBytes = 1232, kRootBytes = 72, kLeafBytes = 144;
constexpr uint64_t kUpperBytes = kUpperEntries * 8 + 2 * kUpperEntries / 8 + 12;
constexpr uint64_t kLowerBytes = kLowerEntries * 8 + 2 * kLowerEntries / 8 + 12;

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
    bool full() const { return full_leaves == kLowerEntries; }
};
struct UpperNode {
    uint64_t key;       // its root entry
    size_t first, end;  // its lower nodes
    size_t full_lowers = 0;
    bool full() const { return full_lowers == kUpperEntries; }
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

void put_string(BlockWriter& sink, const std::string& text) {
    sink.little_endian(int32_t(text.size()));
    sink.text(text);
}

// A random (version 4) UUID in lowercase hex, as OpenVDB puts one in every file it writes.
std::string random_uuid() {
    std::random_device entropy;
    std::array<uint8_t, 16> bits{};
    for (uint8_t& b : bits) b = uint8_t(entropy());
    bits[6] = uint8_t((bits[6] & 0x0f) | 0x40);  // version 4
    bits[8] = uint8_t((bits[8] & 0x3f) | 0x80);  // the RFC 4122 variant
    static const char kHex[] = "0123456789abcdef";
    std::string text;
    for (size_t i = 0; i < bits.size(); ++i) {
        if (i == 4 || i == 6 || i == 8 || i == 10) text += '-';
        text += kHex[bits[i] >> 4];
        text += kHex[bits[i] & 15];
    }
    return text;
}

// The statistics OpenVDB's writer records of a tree (GridBase::addStatsMetadata): the active
// voxels' box (inclusive; an empty box runs from INT32_MAX to INT32_MIN, as OpenVDB's does), their
// count, and the tree's memory as tools::memUsage counts it.
struct TreeStatistics {
    std::array<int32_t, 3> box_min{INT32_MAX, INT32_MAX, INT32_MAX},
        box_max{INT32_MIN, INT32_MIN, INT32_MIN};
    uint64_t active = 0, memory = 0;
};

TreeStatistics tree_statistics(const std::vector<LeafBits>& leaves, const TreeShape& shape) {
    TreeStatistics stats;
    auto expand = [&](const std::array<int32_t, 3>& c) {
        for (int a = 0; a < 3; ++a) {
            stats.box_min[a] = std::min(stats.box_min[a], c[a]);
            stats.box_max[a] = std::max(stats.box_max[a], c[a]);
        }
    };
    for (const LeafBits& leaf : leaves) {
        const auto o = leaf_origin(leaf.key);
        uint64_t yz = 0;
        int x_lo = 8, x_hi = -1;
        for (int x = 0; x < 8; ++x) {
            if (!leaf.words[x]) continue;
            x_lo = std::min(x_lo, x);
            x_hi = x;
            yz |= leaf.words[x];
            stats.active += uint64_t(popcount64(leaf.words[x]));
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
        expand({o[0] + x_lo, o[1] + y_lo, o[2] + z_lo});
        expand({o[0] + x_hi, o[1] + y_hi, o[2] + z_hi});
    }
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

// Everything before the tree: header, grid descriptor, compression, metadata, transform.
void put_grid_prefix(BlockWriter& sink, const Grid& grid, const TreeStatistics& stats) {
    sink.little_endian(int64_t(0x56444220));  // " BDV"
    sink.little_endian(kFileVersion);
    sink.little_endian(kLibraryMajor);
    sink.little_endian(kLibraryMinor);
    sink.little_endian(uint8_t(0));  // no grid offsets
    sink.text(random_uuid());
    sink.little_endian(int32_t(0));  // file metadata
    sink.little_endian(int32_t(1));  // grids
    const std::string name = "occupancy";
    put_string(sink, name);
    put_string(sink, "Tree_bool_5_4_3");
    put_string(sink, "");
    for (int i = 0; i < 3; ++i) sink.little_endian(int64_t(0));
    sink.little_endian(kCompressActiveMask);

    // The grid's metadata, in name order (OpenVDB keeps them in a std::map).
    auto put_entry = [&](const char* key, const char* type, size_t size) {
        put_string(sink, key);
        put_string(sink, type);
        sink.little_endian(int32_t(size));
    };
    auto put_text = [&](const char* key, const std::string& value) {
        put_entry(key, "string", value.size());
        sink.text(value);
    };
    auto put_vec3i = [&](const char* key, const std::array<int32_t, 3>& value) {
        put_entry(key, "vec3i", 12);
        for (const int32_t v : value) sink.little_endian(v);
    };
    auto put_int64 = [&](const char* key, uint64_t value) {
        put_entry(key, "int64", 8);
        sink.little_endian(int64_t(value));
    };
    sink.little_endian(int32_t(10));
    put_text("class", "unknown");
    put_vec3i("file_bbox_max", stats.box_max);
    put_vec3i("file_bbox_min", stats.box_min);
    put_text("file_compression", "active values");
    put_int64("file_mem_bytes", stats.memory);
    put_int64("file_voxel_count", stats.active);
    put_text("name", name);
    put_vec3i("oclvox_dims", {int32_t(grid.dims[0]), int32_t(grid.dims[1]), int32_t(grid.dims[2])});
    put_entry("oclvox_origin", "vec3d", 24);
    for (const double v : grid.origin) sink.little_endian(v);
    put_entry("oclvox_voxel_size", "double", 8);
    sink.little_endian(grid.voxel_size);

    // The transform: OpenVDB's UniformScaleTranslateMap with its derived values, computed as
    // its constructor computes them.
    put_string(sink, "UniformScaleTranslateMap");
    const double scale = grid.voxel_size, inverse = 1.0 / scale;
    for (const double t : vdb_index_origin(grid)) sink.little_endian(t);
    for (const double v :
         {scale, scale, scale, scale, scale, scale, inverse, inverse, inverse, inverse * inverse,
          inverse * inverse, inverse * inverse, inverse / 2, inverse / 2, inverse / 2})
        sink.little_endian(v);
}

}  // namespace

void write_vdb(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress) {
    const size_t gather = progress.add(1), file = progress.add(2);

    // Phase 1: the leaves from the bricks, in OpenVDB's order, the nodes above them, and the
    // statistics the metadata records.
    progress.report(gather, 0, 1);
    const std::vector<LeafBits> leaves = sorted_leaves(voxels);
    const TreeShape shape = tree_shape(leaves);
    const TreeStatistics stats = tree_statistics(leaves, shape);
    progress.report(gather, 1, 1);

    // Phase 2: the file: what precedes the tree, the tree's topology, its leaves' buffers.
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter sink(out);
        put_grid_prefix(sink, voxels.grid(), stats);
        put_topology(sink, leaves, shape);
        put_buffers(sink, leaves, shape,
                    [&](size_t done) { progress.report(file, done, leaves.size()); });
        sink.flush();
        progress.finish();
    });
}

}  // namespace oclvox::detail
