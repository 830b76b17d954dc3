// OpenVDB's file layout, written without OpenVDB's library: what the .vdb files we serialize
// ourselves share (write_vdb.cpp: occupancy; write_level_set_vdb.cpp: level sets). See
// write_vdb.cpp for the layout and for why these files are not written through OpenVDB.
#pragma once

#include <array>
#include <climits>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "block_writer.hpp"
#include "oclvox/field.hpp"
#include "progress.hpp"

namespace oclvox::detail::vdb_stream {

// OpenVDB's standard 5-4-3 tree: a leaf holds 8^3 voxels, a lower node 16^3 leaves, an upper
// node 32^3 lower nodes (4096^3 voxels).
constexpr size_t kLowerEntries = size_t(1) << 12, kUpperEntries = size_t(1) << 15;

// The bytes of a tree's parts as tools::memUsage counts them (OpenVDB 10 on a 64-bit host; the
// same for bool and float trees), for the "file_mem_bytes" metadata: the tree and root objects,
// each internal node's table of 8-byte entries, its two masks and its origin. The byte-for-byte
// tests against OpenVDB's writer check them.
constexpr uint64_t kTreeBytes = 1232, kRootBytes = 72;
constexpr uint64_t kUpperBytes = kUpperEntries * 8 + 2 * kUpperEntries / 8 + 12;
constexpr uint64_t kLowerBytes = kLowerEntries * 8 + 2 * kLowerEntries / 8 + 12;

// Sorting keys sort leaves as OpenVDB writes them: by root entry (its coordinates, x first),
// then offset in the upper node, then offset in the lower node. Grid indices are below 2^20, so
// a root entry's coordinates (index >> 12) fit 8 bits each.
constexpr int kLowerBits = 12, kUpperBits = 15;
uint64_t leaf_key(int64_t x, int64_t y, int64_t z);
std::array<int32_t, 3> leaf_origin(uint64_t key);
// The origin of the upper node (root entry) whose key is `upper_key` (a leaf key's top bits).
inline std::array<int32_t, 3> upper_origin(uint64_t upper_key) {
    return leaf_origin(upper_key << (kUpperBits + kLowerBits));
}

// The bytes of `value` as they lie in memory, as OpenVDB writes its masks and coordinates (its
// files are little-endian, as is every host it supports).
template <class T>
void put_bytes(BlockWriter& sink, const T& value) {
    sink.bytes(reinterpret_cast<const char*>(&value), sizeof(T));
}

// The internal nodes above sorted leaves: each lower node's leaves and each upper node's lower
// nodes, as ranges. `full` counts the entries that are active tiles in a pruned tree (a node whose
// every entry is one is itself an active tile); level sets have none.
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
// `count` leaves in key order: key_of(i), full_of(i) (a leaf every voxel of which is active).
TreeShape tree_shape(size_t count, const std::function<uint64_t(size_t)>& key_of,
                     const std::function<bool(size_t)>& full_of);

// The statistics OpenVDB's writer records of a tree (GridBase::addStatsMetadata): the active
// voxels' box (inclusive; an empty box runs from INT32_MAX to INT32_MIN, as OpenVDB's does), their
// count, and the tree's memory as tools::memUsage counts it.
struct TreeStatistics {
    std::array<int32_t, 3> box_min{INT32_MAX, INT32_MAX, INT32_MAX},
        box_max{INT32_MIN, INT32_MIN, INT32_MIN};
    uint64_t active = 0, memory = 0;
    // Counts a leaf's active voxels (its value mask: word x, bit y * 8 + z) into the box and count.
    void add_leaf(uint64_t key, const uint64_t* words);
};

// What the grid's descriptor and metadata say besides our grid and the statistics.
struct GridDescription {
    std::string name, tree_type, grid_class;
    double band_voxels = 0;  // > 0: recorded as "oclvox_band_voxels"
};

// Everything before the tree: header, grid descriptor, compression ("active mask" only),
// metadata (in name order), transform (index (i, j, k) at our voxel (i, j, k)'s centre).
void put_grid_prefix(BlockWriter& sink, const Grid& grid, const GridDescription& description,
                     const TreeStatistics& stats);

}  // namespace oclvox::detail::vdb_stream

namespace oclvox::detail {

// A level-set FloatGrid "sdf", byte for byte what OpenVDB's writer makes of the same level set
// but for its optional delayed-load index. See write_level_set_vdb.cpp. Throws OutputError.
// A sparse field's leaves, its band field.band_voxels():
void write_level_set_vdb(const std::string& path, const SparseField& field,
                         ProgressPhases& progress);
// A dense field's layers, from layer(k, out) in order, 8 (a leaf's height) held at a time;
// band_voxels <= 0 takes the largest |value| (every leaf is kept until it is known).
void write_level_set_vdb(const std::string& path, const Grid& grid, double band_voxels,
                         const FieldLayer& layer, ProgressPhases& progress);

}  // namespace oclvox::detail
