// OpenVDB level-set writer, without OpenVDB: a FloatGrid named "sdf" of class "level set", sample
// (i, j, k) at index (i, j, k) (the transform of every .vdb we write), its background the band in
// world units, a voxel active where |value| < background, every other value the background signed
// as OpenVDB's signed flood fill signs it. Sparse fields are written from their leaves, dense ones
// from their layers, 8 (a leaf's height) held at a time, keeping the leaves with a sample in the
// band; both give the same file for the same values.
//
// Why not through OpenVDB (as until 2026-12-07): building its tree allocates each leaf (2 KiB,
// 0.3 M of them at 2048^3, fresh pages the kernel must clear), and its serial writer then
// compresses each leaf with Blosc, which gains 6-8% on distances: for bunny00 at 2048^3 the tree
// was 1.6 s and the file 2.8 s against a 2.5 s field. Here the leaves' masks and signs are worked
// out on every core from the field's own leaves (or layers), which are then written from where
// they lie.
//
// The layout is that of write_vdb.cpp (OpenVDB file format 224, one grid, a 5-4-3 tree,
// compression "active mask" only) with float values. What differs from a bool tree:
//   - every value that is not active is +background or -background. OpenVDB's signed flood fill
//     gives them their sign, bottom up: in a leaf, scanning x, then y, then z (offset order),
//     each inactive value takes the sign of the last active value met along the scan (the first
//     active value's before any); in an internal node, each tile takes the sign of the last
//     child's last value met the same way; at the root, the gaps along z between two upper nodes
//     with the same x and y whose facing values are both inside become inside tiles (inactive).
//   - a value array (a leaf's buffer, an internal node's tiles) is written as OpenVDB's
//     writeCompressedValues writes it: one metadata byte, 0 if every inactive value is
//     +background, 1 if every one is -background, else 3 and a mask of those that are
//     +background; then the active values (internal nodes have none).
//   - the root starts with the background (a float), and its tiles are (x, y, z, value, active).
//   - a leaf's buffer is its value mask then its compressed values (no origin).

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>

#include "atomic_file.hpp"
#include "bit_count.hpp"
#include "host_memory.hpp"
#include "vdb_stream.hpp"

namespace oclvox::detail {

namespace {

using namespace vdb_stream;

// A float leaf object's bytes as tools::memUsage counts them: the object and its 512 values.
constexpr uint64_t kLeafBytes = 2144;

constexpr uint8_t kAllOutside = 0, kAllInside = 1, kSelectOutside = 3;  // writeCompressedValues

// The leaves to write, in any order: count, each one's minimum voxel and its 512 samples (x
// fastest; those beyond the grid are never read), and the level set's background and band.
struct LeafSource {
    const Grid& grid;
    float background;
    double band_voxels;
    size_t count;
    std::function<std::array<int64_t, 3>(size_t)> origin;
    std::function<const float*(size_t)> samples;
};

// A leaf as written: its key, the source's leaf it comes from, its value mask, which of its
// inactive values are inside (-background) after the flood fill, and whether its first and last
// values (offsets 0 and 511) are inside, which its parent's flood fill reads.
struct LevelSetLeaf {
    uint64_t key;
    size_t stored;  // the source's n-th leaf
    uint64_t active[8];
    uint64_t inside[8];
    bool first_inside, last_inside;
};

// The metadata byte of a value array whose non-child inactive entries are `outside`
// (+background) and `inside` (-background) in number.
uint8_t compression_metadata(size_t outside, size_t inside) {
    if (inside == 0) return kAllOutside;
    return outside == 0 ? kAllInside : kSelectOutside;
}

// The leaf's mask and flood-filled signs from the field's samples (x fastest; those beyond the
// grid are inactive). False if no sample is within the band: OpenVDB's tree would hold no leaf.
bool fill_leaf(const float* samples, const std::array<int64_t, 3>& n, float background,
               LevelSetLeaf& leaf) {
    bool any = false;
    for (int x = 0; x < 8; ++x) {
        uint64_t word = 0;
        if (x < n[0])
            for (int y = 0; y < n[1]; ++y)
                for (int z = 0; z < n[2]; ++z)
                    if (std::abs(samples[x + 8 * (y + 8 * z)]) < background)
                        word |= uint64_t(1) << (y << 3 | z);
        leaf.active[x] = word;
        any |= word != 0;
    }
    if (!any) return false;
    auto value_inside = [&](int x, int yz) {
        return samples[x + 8 * ((yz >> 3) + 8 * (yz & 7))] < 0;
    };
    // The scan of SignedFloodFillOp's leaf pass: it starts from the first active value's sign.
    int first_x = 0;
    while (!leaf.active[first_x]) ++first_x;
    bool x_inside = value_inside(first_x, __builtin_ctzll(leaf.active[first_x]));
    for (int x = 0; x < 8; ++x) {
        const uint64_t on = leaf.active[x];
        uint64_t inside = 0;
        if (on & 1) x_inside = value_inside(x, 0);
        bool y_inside = x_inside;
        for (int y = 0; y < 8; ++y) {
            if (on >> (y << 3) & 1) y_inside = value_inside(x, y << 3);
            bool z_inside = y_inside;
            for (int z = 0; z < 8; ++z) {
                const int yz = y << 3 | z;
                if (on >> yz & 1)
                    z_inside = value_inside(x, yz);
                else if (z_inside)
                    inside |= uint64_t(1) << yz;
            }
        }
        leaf.inside[x] = inside;
    }
    leaf.first_inside = (leaf.active[0] & 1) ? value_inside(0, 0) : (leaf.inside[0] & 1) != 0;
    leaf.last_inside = (leaf.active[7] >> 63) ? value_inside(7, 63) : (leaf.inside[7] >> 63) != 0;
    return true;
}

// An internal node of 2^(3 kLog2) entries after the flood fill: which entries are children and
// which tiles are inside, and whether its first and last values are inside.
template <int kLog2>
struct FilledNode {
    static constexpr size_t kEntries = size_t(1) << (3 * kLog2);
    std::array<uint64_t, kEntries / 64> children{}, inside{};
    bool first_inside = false, last_inside = false;

    // offsets: the children's offsets, increasing; child_first(c), child_last(c): whether child
    // c's first and last values are inside.
    template <class FirstInside, class LastInside>
    void fill(const std::vector<uint32_t>& offsets, const FirstInside& child_first,
              const LastInside& child_last) {
        std::vector<int32_t> at(kEntries, -1);
        for (size_t c = 0; c < offsets.size(); ++c) {
            at[offsets[c]] = int32_t(c);
            children[offsets[c] >> 6] |= uint64_t(1) << (offsets[c] & 63);
        }
        bool x_inside = child_first(0);  // the first child's first value
        constexpr size_t kDim = size_t(1) << kLog2;
        for (size_t x = 0; x < kDim; ++x) {
            const size_t x00 = x << (2 * kLog2);
            if (at[x00] >= 0) x_inside = child_last(size_t(at[x00]));
            bool y_inside = x_inside;
            for (size_t y = 0; y < kDim; ++y) {
                const size_t xy0 = x00 + (y << kLog2);
                if (at[xy0] >= 0) y_inside = child_last(size_t(at[xy0]));
                bool z_inside = y_inside;
                for (size_t z = 0; z < kDim; ++z) {
                    const size_t xyz = xy0 + z;
                    if (at[xyz] >= 0)
                        z_inside = child_last(size_t(at[xyz]));
                    else if (z_inside)
                        inside[xyz >> 6] |= uint64_t(1) << (xyz & 63);
                }
            }
        }
        first_inside = at[0] >= 0 ? child_first(size_t(at[0])) : (inside[0] & 1) != 0;
        last_inside = at[kEntries - 1] >= 0 ? child_last(size_t(at[kEntries - 1]))
                                            : (inside.back() >> 63) != 0;
    }

    // Child mask, value mask (no active tiles), the tiles' compressed values (none active).
    void put(BlockWriter& sink) const {
        put_bytes(sink, children);
        put_bytes(sink, std::array<uint64_t, kEntries / 64>{});
        size_t tiles_inside = 0, child_count = 0;
        for (size_t w = 0; w < kEntries / 64; ++w) {
            tiles_inside += size_t(popcount64(inside[w]));
            child_count += size_t(popcount64(children[w]));
        }
        const uint8_t metadata =
            compression_metadata(kEntries - child_count - tiles_inside, tiles_inside);
        sink.little_endian(metadata);
        if (metadata != kSelectOutside) return;
        std::array<uint64_t, kEntries / 64> outside;
        for (size_t w = 0; w < kEntries / 64; ++w) outside[w] = ~(children[w] | inside[w]);
        put_bytes(sink, outside);
    }
};
using LowerFill = FilledNode<4>;
using UpperFill = FilledNode<5>;

// The leaves within the band, in OpenVDB's order, with their masks and signs.
std::vector<LevelSetLeaf> level_set_leaves(const LeafSource& source) {
    const size_t count = source.count;
    std::vector<std::pair<uint64_t, size_t>> order(count);
    tbb::parallel_for(size_t(0), count, [&](size_t n) {
        const auto o = source.origin(n);
        order[n] = {leaf_key(o[0], o[1], o[2]), n};
    });
    tbb::parallel_sort(order.begin(), order.end());
    std::vector<LevelSetLeaf> leaves(count);
    std::vector<uint8_t> kept(count);
    const auto& d = source.grid.dims;
    tbb::parallel_for(size_t(0), count, [&](size_t i) {
        const size_t n = order[i].second;
        const auto o = source.origin(n);
        const std::array<int64_t, 3> inside_grid{std::min<int64_t>(8, d[0] - o[0]),
                                                 std::min<int64_t>(8, d[1] - o[1]),
                                                 std::min<int64_t>(8, d[2] - o[2])};
        LevelSetLeaf& leaf = leaves[i];
        leaf.key = order[i].first;
        leaf.stored = n;
        kept[i] = fill_leaf(source.samples(n), inside_grid, source.background, leaf);
    });
    size_t used = 0;
    for (size_t i = 0; i < count; ++i)
        if (kept[i]) leaves[used++] = leaves[i];
    leaves.resize(used);
    return leaves;
}

// A leaf's buffer: value mask, compressed values (metadata, the mask of +background values if
// both signs occur, the active values in offset order).
void put_leaf_buffer(BlockWriter& sink, const LevelSetLeaf& leaf, const float* samples) {
    put_bytes(sink, leaf.active);
    size_t inactive = 0, inside = 0;
    for (int x = 0; x < 8; ++x) {
        inactive += size_t(64 - popcount64(leaf.active[x]));
        inside += size_t(popcount64(leaf.inside[x]));
    }
    const uint8_t metadata = compression_metadata(inactive - inside, inside);
    sink.little_endian(metadata);
    if (metadata == kSelectOutside) {
        uint64_t outside[8];
        for (int x = 0; x < 8; ++x) outside[x] = ~(leaf.active[x] | leaf.inside[x]);
        put_bytes(sink, outside);
    }
    for (int x = 0; x < 8; ++x)
        for (uint64_t on = leaf.active[x]; on; on &= on - 1) {
            const int yz = __builtin_ctzll(on);
            sink.little_endian(samples[x + 8 * ((yz >> 3) + 8 * (yz & 7))]);
        }
}

void write_leaves(const std::string& path, const LeafSource& source, ProgressPhases& progress) {
    const size_t gather = progress.add(1), file = progress.add(2);
    const float background = source.background;

    // Phase 1: the leaves in the band, in OpenVDB's order, with their signs; the nodes above
    // them, flood-filled bottom up; the statistics the metadata records.
    progress.report(gather, 0, 1);
    const std::vector<LevelSetLeaf> leaves = level_set_leaves(source);
    const TreeShape shape = tree_shape(
        leaves.size(), [&](size_t i) { return leaves[i].key; }, [](size_t) { return false; });
    std::vector<LowerFill> lowers(shape.lowers.size());
    tbb::parallel_for(size_t(0), lowers.size(), [&](size_t l) {
        const LowerNode& node = shape.lowers[l];
        std::vector<uint32_t> offsets;
        for (size_t i = node.first; i < node.end; ++i)
            offsets.push_back(uint32_t(leaves[i].key & (kLowerEntries - 1)));
        lowers[l].fill(
            offsets, [&](size_t c) { return leaves[node.first + c].first_inside; },
            [&](size_t c) { return leaves[node.first + c].last_inside; });
    });
    std::vector<UpperFill> uppers(shape.uppers.size());
    tbb::parallel_for(size_t(0), uppers.size(), [&](size_t u) {
        const UpperNode& node = shape.uppers[u];
        std::vector<uint32_t> offsets;
        for (size_t l = node.first; l < node.end; ++l)
            offsets.push_back(uint32_t(shape.lowers[l].key & (kUpperEntries - 1)));
        uppers[u].fill(
            offsets, [&](size_t c) { return lowers[node.first + c].first_inside; },
            [&](size_t c) { return lowers[node.first + c].last_inside; });
    });
    // The root's inside tiles: the gaps along z between upper nodes of one (x, y) whose facing
    // values are inside.
    std::vector<std::array<int32_t, 3>> root_tiles;
    for (size_t u = 1; u < shape.uppers.size(); ++u) {
        const auto a = upper_origin(shape.uppers[u - 1].key);
        const auto b = upper_origin(shape.uppers[u].key);
        if (a[0] != b[0] || a[1] != b[1] || b[2] - a[2] == 4096) continue;
        if (!uppers[u - 1].last_inside || !uppers[u].first_inside) continue;
        for (int32_t z = a[2] + 4096; z != b[2]; z += 4096) root_tiles.push_back({a[0], a[1], z});
    }
    TreeStatistics stats;
    for (const LevelSetLeaf& leaf : leaves) stats.add_leaf(leaf.key, leaf.active);
    stats.memory = kTreeBytes + kRootBytes + shape.uppers.size() * kUpperBytes +
                   shape.lowers.size() * kLowerBytes + leaves.size() * kLeafBytes;
    progress.report(gather, 1, 1);

    // Phase 2: the file: what precedes the tree, the tree's topology, its leaves' buffers.
    write_file_atomically(path, [&](std::ostream& out) {
        BlockWriter sink(out);
        put_grid_prefix(sink, source.grid,
                        {"sdf", "Tree_float_5_4_3", "level set", source.band_voxels}, stats);
        sink.little_endian(int32_t(1));  // buffer count
        sink.little_endian(background);
        sink.little_endian(uint32_t(root_tiles.size()));
        sink.little_endian(uint32_t(shape.uppers.size()));
        for (const auto& tile : root_tiles) {
            put_bytes(sink, tile);
            sink.little_endian(-background);
            sink.little_endian(uint8_t(0));  // inactive
        }
        for (size_t u = 0; u < shape.uppers.size(); ++u) {
            put_bytes(sink, upper_origin(shape.uppers[u].key));
            uppers[u].put(sink);
            for (size_t l = shape.uppers[u].first; l < shape.uppers[u].end; ++l) {
                lowers[l].put(sink);
                for (size_t i = shape.lowers[l].first; i < shape.lowers[l].end; ++i)
                    put_bytes(sink, leaves[i].active);
            }
        }
        for (size_t i = 0; i < leaves.size(); ++i) {
            put_leaf_buffer(sink, leaves[i], source.samples(leaves[i].stored));
            if ((i & 4095) == 4095) progress.report(file, i + 1, leaves.size());
        }
        sink.flush();
        progress.finish();
    });
}

}  // namespace

void write_level_set_vdb(const std::string& path, const SparseField& field,
                         ProgressPhases& progress) {
    write_leaves(path,
                 {field.grid(), field.background(), field.band_voxels(), field.leaf_count(),
                  [&](size_t n) { return field.leaf_origin(field.leaf_indices()[n]); },
                  [&](size_t n) { return field.leaf_samples(n); }},
                 progress);
}

void write_level_set_vdb(const std::string& path, const Grid& grid, double band_voxels,
                         const FieldLayer& layer, ProgressPhases& progress) {
    // Phase 1: the leaves with a sample in the band, gathered from slabs of a leaf's height of
    // layers. Without a band, every leaf is kept until the band (the largest |value|) is known.
    const size_t slabs = progress.add(2);
    const bool band_known = band_voxels > 0;
    const float band = band_known ? float(band_voxels * grid.voxel_size) : INFINITY;
    const auto& d = grid.dims;
    const int64_t leaves_x = (d[0] + 7) / 8, leaves_y = (d[1] + 7) / 8;
    const size_t per_layer = size_t(d[0]) * size_t(d[1]), per_slab = size_t(leaves_x * leaves_y);
    // Without a band every leaf is held, so the grid's leaves must fit the host memory budget;
    // checked before the first layer is asked for (a full grid computes its slabs as they are).
    if (!band_known)
        check_host_memory(
            uint64_t(per_slab) * uint64_t((d[2] + 7) / 8) *
                (SparseField::kLeafSamples * sizeof(float) + sizeof(std::array<int64_t, 3>)),
            default_host_budget(),
            "a .vdb of every sample of " + std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" +
                std::to_string(d[2]) +
                " voxels (all its leaves are held until its band, the largest "
                "distance, is known; .npy is written a layer at a time)");
    std::vector<float> slab(per_layer * 8), slab_leaves(per_slab * SparseField::kLeafSamples);
    std::vector<uint8_t> in_band(per_slab);
    std::vector<std::array<int64_t, 3>> origins;
    std::vector<float> samples;
    float largest = 0;
    for (int64_t z = 0; z < d[2]; z += 8) {
        progress.report(slabs, uint64_t(z), uint64_t(d[2]));
        const int64_t depth = std::min<int64_t>(8, d[2] - z);
        for (int64_t k = 0; k < depth; ++k) layer(z + k, &slab[size_t(k) * per_layer]);
        const float slab_largest = tbb::parallel_reduce(
            tbb::blocked_range<size_t>(0, per_slab), 0.0f,
            [&](const tbb::blocked_range<size_t>& r, float most) {
                for (size_t i = r.begin(); i != r.end(); ++i) {
                    const int64_t x = int64_t(i) % leaves_x * 8, y = int64_t(i) / leaves_x * 8;
                    const int64_t row = std::min<int64_t>(8, d[0] - x);
                    float* leaf = &slab_leaves[i * SparseField::kLeafSamples];
                    bool any = false;
                    for (int64_t k = 0; k < depth; ++k)
                        for (int64_t j = y; j < std::min(y + 8, d[1]); ++j) {
                            const float* from = &slab[size_t(k) * per_layer + size_t(x + d[0] * j)];
                            std::copy_n(from, row, &leaf[8 * ((j - y) + 8 * k)]);
                            for (int64_t n = 0; n < row; ++n) {
                                most = std::max(most, std::abs(from[n]));
                                any |= std::abs(from[n]) < band;
                            }
                        }
                    in_band[i] = any;
                }
                return most;
            },
            [](float a, float b) { return std::max(a, b); });
        largest = std::max(largest, slab_largest);
        for (size_t i = 0; i < per_slab; ++i) {
            if (!in_band[i]) continue;
            origins.push_back({int64_t(i) % leaves_x * 8, int64_t(i) / leaves_x * 8, z});
            const float* leaf = &slab_leaves[i * SparseField::kLeafSamples];
            samples.insert(samples.end(), leaf, leaf + SparseField::kLeafSamples);
        }
    }
    progress.report(slabs, 1, 1);

    // Phase 2: the file. A band found from the samples is their largest |value|: those at it are
    // the background (inactive), and leaves left without an active sample are not written.
    write_leaves(path,
                 {grid, band_known ? band : largest,
                  band_known ? band_voxels : double(largest) / grid.voxel_size, origins.size(),
                  [&](size_t n) { return origins[n]; },
                  [&](size_t n) { return &samples[n * SparseField::kLeafSamples]; }},
                 progress);
}

}  // namespace oclvox::detail
