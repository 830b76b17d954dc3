// MagicaVoxel .vox writer (github.com/ephtracy/voxel-model: MagicaVoxel-file-format-vox.txt and
// MagicaVoxel-file-format-vox-extension.txt).
//
// A model holds at most 256 voxels per axis (coordinates are single bytes), so the grid is cut
// into 256^3 tiles and every tile with a set voxel becomes one model (SIZE + XYZI chunks). The
// scene graph places them: root transform -> group -> (transform -> shape) per model. A
// transform's translation "_t" is where the model's centre goes, and the centre of a model of
// size s is voxel floor(s / 2), so a tile starting at voxel o gets _t = o + floor(s / 2).
//
// Older readers (before the scene graph) take the file too: a PACK chunk gives the model count,
// the scene graph chunks are ones they skip, and every shape sits in layer 0, which a LAYR
// chunk names.
//
// Streaming: the models are written tile by tile straight from the bricks. A first pass counts
// each tile's voxels (popcounts of its blocks, the tiles in parallel), which fixes every chunk
// size before anything is written; the second writes each tile's voxels in a fixed order (4^3
// blocks in z, y, x order within the tile, bits in block order), walking the tile's blocks in
// that order through a table of its bricks, a layer of blocks (4 voxel layers) at a time: the
// layers are the parts of one stream (stream_parts), made on every core while the slab of layers
// before is written. So the file does not depend on the brick size, hash order or cores, and the
// largest buffers are two slabs of block layers (at most 1 MiB each).
//
// Axes are kept as they are (MagicaVoxel treats z as up). The format has no units, so the grid's
// origin and voxel size are not recorded; positions are voxel indices. Every voxel uses colour
// index 1 of the default palette, so no RGBA chunk is written.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <sstream>
#include <vector>

#include "atomic_file.hpp"
#include "bit_count.hpp"
#include "block_writer.hpp"
#include "brick_layout.hpp"
#include "little_endian.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

constexpr int64_t kTile = 256;
constexpr int64_t kBlocksPerTileAxis = kTile / SparseVoxels::kBlock;
// The most bytes of voxels a tile's layer of blocks can hold (4 bytes a voxel): the parts of the
// model stream.
constexpr uint64_t kTileLayerBytes = 4 * kTile * kTile * SparseVoxels::kBlock;
constexpr uint8_t kColorIndex = 1;
// 150 is the version MagicaVoxel 0.99 wrote when it introduced the scene graph chunks; readers
// that know the scene graph accept it.
constexpr int32_t kVersion = 150;
constexpr size_t kChunkHeader = 12;  // id, content size, children size

void write_i32(std::ostream& out, int32_t value) {
    write_le(out, value);
}

void write_chunk_header(std::ostream& out, const char* id, size_t content, size_t children) {
    out.write(id, 4);
    write_i32(out, int32_t(content));
    write_i32(out, int32_t(children));
}

// Chunk: 4-byte id, content size, children size, content, children.
void write_chunk(std::ostream& out, const char* id, const std::string& content) {
    write_chunk_header(out, id, content.size(), 0);
    out << content;
}

void write_string(std::ostream& out, const std::string& text) {
    write_i32(out, int32_t(text.size()));
    out << text;
}

// DICT of key/value strings.
void write_dict(std::ostream& out, const std::vector<std::pair<std::string, std::string>>& dict) {
    write_i32(out, int32_t(dict.size()));
    for (const auto& [key, value] : dict) {
        write_string(out, key);
        write_string(out, value);
    }
}

// nTRN with one frame. The root has no layer (-1) and no translation.
std::string transform_node(int32_t id, int32_t child, int32_t layer,
                           const std::string& translation) {
    std::ostringstream out;
    write_i32(out, id);
    write_dict(out, {});
    write_i32(out, child);
    write_i32(out, -1);  // reserved
    write_i32(out, layer);
    write_i32(out, 1);  // frames
    if (translation.empty())
        write_dict(out, {});
    else
        write_dict(out, {{"_t", translation}});
    return out.str();
}

std::string group_node(int32_t id, const std::vector<int32_t>& children) {
    std::ostringstream out;
    write_i32(out, id);
    write_dict(out, {});
    write_i32(out, int32_t(children.size()));
    for (int32_t child : children) write_i32(out, child);
    return out.str();
}

std::string shape_node(int32_t id, int32_t model) {
    std::ostringstream out;
    write_i32(out, id);
    write_dict(out, {});
    write_i32(out, 1);  // models
    write_i32(out, model);
    write_dict(out, {});
    return out.str();
}

std::string layer_chunk(int32_t id) {
    std::ostringstream out;
    write_i32(out, id);
    write_dict(out, {{"_name", "oclvox"}});
    write_i32(out, -1);  // reserved
    return out.str();
}

// One 256^3 tile of the grid and the stored bricks that overlap it.
struct Tile {
    std::array<int64_t, 3> coords{};  // tile index along each axis
    std::vector<uint64_t> bricks;
    uint64_t voxels = 0;
};

// The stored bricks a tile's blocks lie in, as a table over their brick coordinates (null where
// none is stored), so that walking the tile's blocks in order asks the bricks' map once per brick.
struct TileBricks {
    std::array<int64_t, 3> first{}, count{};  // brick coordinates
    std::vector<const uint64_t*> blocks;
    const uint64_t* at(int64_t bx, int64_t by, int64_t bz) const {
        return blocks[size_t((bx - first[0]) +
                             count[0] * ((by - first[1]) + count[1] * (bz - first[2])))];
    }
};

class TileWalker {
  public:
    explicit TileWalker(const SparseVoxels& voxels)
        : voxels_(voxels), layout_(voxels), brick_size_(voxels.brick_size()) {}

    // The tiles with a set voxel, in (z, y, x) tile order, with their bricks and voxel counts.
    std::vector<Tile> tiles() const {
        const auto& dims = voxels_.grid().dims;
        const std::array<int64_t, 3> ntiles{(dims[0] + kTile - 1) / kTile,
                                            (dims[1] + kTile - 1) / kTile,
                                            (dims[2] + kTile - 1) / kTile};
        std::vector<std::pair<uint64_t, uint64_t>> tile_of_brick;  // (tile key, brick)
        for (const uint64_t brick : voxels_.brick_indices()) {
            const auto lo = layout_.brick_origin(brick);
            std::array<int64_t, 3> first{}, last{};
            for (int a = 0; a < 3; ++a) {
                first[a] = lo[a] / kTile;
                last[a] = (std::min(lo[a] + brick_size_, dims[a]) - 1) / kTile;
            }
            for (int64_t tz = first[2]; tz <= last[2]; ++tz)
                for (int64_t ty = first[1]; ty <= last[1]; ++ty)
                    for (int64_t tx = first[0]; tx <= last[0]; ++tx)
                        tile_of_brick.push_back(
                            {uint64_t(tx + ntiles[0] * (ty + ntiles[1] * tz)), brick});
        }
        std::sort(tile_of_brick.begin(), tile_of_brick.end());

        std::vector<Tile> tiles;
        for (size_t e = 0; e < tile_of_brick.size(); ++e) {
            const uint64_t key = tile_of_brick[e].first;
            if (e == 0 || tile_of_brick[e - 1].first != key) {
                Tile tile;
                tile.coords = {int64_t(key % uint64_t(ntiles[0])),
                               int64_t(key / uint64_t(ntiles[0]) % uint64_t(ntiles[1])),
                               int64_t(key / uint64_t(ntiles[0] * ntiles[1]))};
                tiles.push_back(tile);
            }
            tiles.back().bricks.push_back(tile_of_brick[e].second);
        }
        tbb::parallel_for(size_t(0), tiles.size(),
                          [&](size_t t) { tiles[t].voxels = voxels_in(tiles[t]); });
        tiles.erase(
            std::remove_if(tiles.begin(), tiles.end(), [](const Tile& t) { return t.voxels == 0; }),
            tiles.end());
        return tiles;
    }

    // The table of the bricks tile's blocks lie in.
    TileBricks bricks_of(const Tile& tile) const {
        const auto& dims = voxels_.grid().dims;
        const int64_t per_brick = brick_size_ / SparseVoxels::kBlock;
        TileBricks table;
        for (int a = 0; a < 3; ++a) {
            const int64_t first_block = tile.coords[a] * kBlocksPerTileAxis;
            const int64_t end_block =
                std::min(first_block + kBlocksPerTileAxis,
                         (dims[a] + SparseVoxels::kBlock - 1) / SparseVoxels::kBlock);
            table.first[a] = first_block / per_brick;
            table.count[a] = (end_block - 1) / per_brick - table.first[a] + 1;
        }
        const auto nb = voxels_.brick_dims();
        table.blocks.reserve(size_t(table.count[0] * table.count[1] * table.count[2]));
        for (int64_t bz = table.first[2]; bz < table.first[2] + table.count[2]; ++bz)
            for (int64_t by = table.first[1]; by < table.first[1] + table.count[1]; ++by)
                for (int64_t bx = table.first[0]; bx < table.first[0] + table.count[0]; ++bx)
                    table.blocks.push_back(
                        voxels_.brick_blocks(uint64_t(bx + nb[0] * (by + nb[1] * bz))));
        return table;
    }

    // The XYZI words of the voxels of the tile's block layer lz (the tile's blocks at that z) to
    // `w`, in the file's order: blocks x fastest, then y, each block's voxels in bit order. A
    // voxel's word is its block's word plus its place in the block (no byte carries: a tile
    // coordinate is at most 255), so a full block, most of a solid, is 64 sums written at once.
    void write_layer(const Tile& tile, const TileBricks& bricks, int64_t lz, BlockWriter& w) const {
        static const std::array<uint32_t, 64> in_block = [] {
            std::array<uint32_t, 64> words{};
            for (int bit = 0; bit < 64; ++bit) {
                const auto v = voxel_in_block(bit);
                words[size_t(bit)] = uint32_t(v[0]) | uint32_t(v[1]) << 8 | uint32_t(v[2]) << 16;
            }
            return words;
        }();
        const auto& dims = voxels_.grid().dims;
        const int64_t per_brick = brick_size_ / SparseVoxels::kBlock;
        std::array<int64_t, 3> first{}, end{};  // the tile's blocks, in grid block coordinates
        for (int a = 0; a < 3; ++a) {
            first[a] = tile.coords[a] * kBlocksPerTileAxis;
            end[a] = std::min(first[a] + kBlocksPerTileAxis,
                              (dims[a] + SparseVoxels::kBlock - 1) / SparseVoxels::kBlock);
        }
        const int64_t gz = first[2] + lz;
        if (gz >= end[2]) return;
        char full[64 * 4];
        for (int64_t gy = first[1]; gy < end[1]; ++gy)
            for (int64_t gx = first[0]; gx < end[0];) {
                // The run of the row's blocks in one brick.
                const int64_t run_end = std::min(end[0], (gx / per_brick + 1) * per_brick);
                const uint64_t* blocks = bricks.at(gx / per_brick, gy / per_brick, gz / per_brick);
                if (!blocks) {
                    gx = run_end;
                    continue;
                }
                const uint64_t* row =
                    blocks + per_brick * (gy % per_brick + per_brick * (gz % per_brick));
                for (; gx < run_end; ++gx) {
                    const uint64_t bits = row[gx % per_brick];
                    if (!bits) continue;
                    const uint32_t base = uint32_t(4 * (gx - first[0])) |
                                          uint32_t(4 * (gy - first[1])) << 8 |
                                          uint32_t(4 * lz) << 16 | uint32_t(kColorIndex) << 24;
                    if (bits == ~uint64_t(0)) {
                        for (size_t bit = 0; bit < 64; ++bit)
                            store_le(full + 4 * bit, base + in_block[bit]);
                        w.bytes(full, sizeof full);
                        continue;
                    }
                    for (uint64_t mask = bits; mask; mask &= mask - 1)
                        w.little_endian(base + in_block[size_t(__builtin_ctzll(mask))]);
                }
            }
    }

  private:
    // The set voxels of the tile's blocks (of its bricks, those inside it): a brick inside the
    // tile (every brick, where the brick size divides the tile's) counted whole, the others block
    // by block.
    uint64_t voxels_in(const Tile& tile) const {
        const int64_t per_brick = brick_size_ / SparseVoxels::kBlock;
        uint64_t count = 0;
        for (const uint64_t brick : tile.bricks) {
            const uint64_t* words = voxels_.brick_blocks(brick);
            const auto o = layout_.brick_origin(brick);
            std::array<int64_t, 3> lo{}, hi{};  // the brick's blocks inside the tile
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::max<int64_t>(0, tile.coords[a] * kTile - o[a]) / SparseVoxels::kBlock;
                hi[a] = std::min<int64_t>(
                    per_brick, ((tile.coords[a] + 1) * kTile - o[a]) / SparseVoxels::kBlock);
            }
            if (lo == std::array<int64_t, 3>{} &&
                hi == std::array<int64_t, 3>{per_brick, per_brick, per_brick}) {
                count += count_bits(words, layout_.blocks_per_brick());
                continue;
            }
            for (int64_t z = lo[2]; z < hi[2]; ++z)
                for (int64_t y = lo[1]; y < hi[1]; ++y)
                    count += count_bits(words + per_brick * (y + per_brick * z) + lo[0],
                                        size_t(hi[0] - lo[0]));
        }
        return count;
    }

    const SparseVoxels& voxels_;
    BrickLayout layout_;
    int64_t brick_size_;
};

std::array<int64_t, 3> tile_size(const Grid& grid, const Tile& tile) {
    std::array<int64_t, 3> size{};
    for (int a = 0; a < 3; ++a) size[a] = std::min(kTile, grid.dims[a] - tile.coords[a] * kTile);
    return size;
}

}  // namespace

void write_vox(const std::string& path, const SparseVoxels& voxels, ProgressPhases& progress) {
    const Grid& grid = voxels.grid();

    // Phase 1: the tiles with set voxels and their counts. An empty grid still gets one (empty)
    // model so the file has the structure every reader expects.
    const TileWalker walker(voxels);
    std::vector<Tile> tiles = walker.tiles();
    if (tiles.empty()) tiles.push_back(Tile{});

    // Phase 2: the scene graph (small), and the size of everything inside MAIN. Node ids: 0 root
    // transform, 1 group, then 2m + 2 and 2m + 3 for the transform and shape of model m.
    std::ostringstream scene;
    std::vector<int32_t> group_children;
    uint64_t models_bytes = 0;
    for (size_t m = 0; m < tiles.size(); ++m) {
        const auto size = tile_size(grid, tiles[m]);
        std::array<int64_t, 3> centre{};
        for (int a = 0; a < 3; ++a) centre[a] = tiles[m].coords[a] * kTile + size[a] / 2;
        const int32_t transform_id = 2 * int32_t(m) + 2, shape_id = transform_id + 1;
        group_children.push_back(transform_id);
        const std::string translation = std::to_string(centre[0]) + " " +
                                        std::to_string(centre[1]) + " " + std::to_string(centre[2]);
        write_chunk(scene, "nTRN", transform_node(transform_id, shape_id, 0, translation));
        write_chunk(scene, "nSHP", shape_node(shape_id, int32_t(m)));
        models_bytes += kChunkHeader + 12 + kChunkHeader + 4 + 4 * tiles[m].voxels;
    }
    std::ostringstream graph;
    write_chunk(graph, "nTRN", transform_node(0, 1, -1, ""));
    write_chunk(graph, "nGRP", group_node(1, group_children));
    graph << scene.str();
    write_chunk(graph, "LAYR", layer_chunk(0));
    const std::string graph_bytes = graph.str();
    const uint64_t main_children = kChunkHeader + 4 + models_bytes + graph_bytes.size();
    if (main_children > uint64_t(std::numeric_limits<int32_t>::max()))
        throw OutputError("cannot write " + path + ": " + std::to_string(voxels.count()) +
                          " voxels exceed the 2 GiB a .vox file can hold; write .vdb instead");

    // Phase 3: magic, version, MAIN, PACK, the models tile by tile, then the scene graph. The
    // models are the parts of one stream (stream_parts): a tile's block layers, the first with
    // the tile's SIZE and XYZI headers, each made on any core while the slab before is written.
    const size_t models = progress.add(1);
    // Part p of the stream is block layer p % kBlocksPerTileAxis of tile p / kBlocksPerTileAxis.
    const int64_t parts = int64_t(tiles.size()) * kBlocksPerTileAxis;
    write_file_atomically(path, [&](std::ostream& out) {
        out.write("VOX ", 4);
        write_i32(out, kVersion);
        write_chunk_header(out, "MAIN", 0, main_children);
        write_chunk_header(out, "PACK", 4, 0);
        write_i32(out, int32_t(tiles.size()));
        std::vector<TileBricks> bricks(tiles.size());
        size_t released = 0;  // tiles whose tables are let go
        stream_parts<PartsSlab>(
            &out, parts, parts_per_slab(kTileLayerBytes),
            [&](PartsSlab& slab, int64_t first, int64_t end) {
                // The table of a tile the slab begins, before its parts are made; those of the
                // tiles before the slab's first are let go.
                const size_t first_tile = size_t(first / kBlocksPerTileAxis);
                for (; released < first_tile; ++released) bricks[released] = TileBricks{};
                for (size_t m = first_tile; m <= size_t((end - 1) / kBlocksPerTileAxis); ++m)
                    if (int64_t(m) * kBlocksPerTileAxis >= first)
                        bricks[m] = walker.bricks_of(tiles[m]);
                tbb::parallel_for(first, end, [&](int64_t part) {
                    const size_t m = size_t(part / kBlocksPerTileAxis);
                    const int64_t lz = part % kBlocksPerTileAxis;
                    BlockWriter& w = slab.bytes[size_t(part - first)];
                    if (lz == 0) {
                        std::ostringstream header;
                        const auto size = tile_size(grid, tiles[m]);
                        write_chunk_header(header, "SIZE", 12, 0);
                        for (int a = 0; a < 3; ++a) write_i32(header, int32_t(size[a]));
                        write_chunk_header(header, "XYZI", 4 + 4 * tiles[m].voxels, 0);
                        write_i32(header, int32_t(tiles[m].voxels));
                        w.text(header.str());
                    }
                    walker.write_layer(tiles[m], bricks[m], lz, w);
                });
            },
            [&](int64_t first) { progress.report(models, uint64_t(first), uint64_t(parts)); });
        out << graph_bytes;
        progress.finish();
    });
}

}  // namespace oclvox::detail
