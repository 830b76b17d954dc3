// MagicaVoxel .vox writer (github.com/ephtracy/voxel-model: MagicaVoxel-file-format-vox.txt and
// MagicaVoxel-file-format-vox-extension.txt).
//
// A model holds at most 256 voxels per axis (coordinates are single bytes), so the grid is cut
// into 256^3 tiles and every tile with a set voxel becomes one model (SIZE + XYZI chunks). The
// scene graph places them: root transform -> group -> (transform -> shape) per model. A
// transform's translation "_t" is where the model's centre goes, and the centre of a model of
// size s is voxel floor(s / 2), so a tile starting at voxel o gets _t = o + floor(s / 2).
//
// Axes are kept as they are (MagicaVoxel treats z as up). The format has no units, so the grid's
// origin and voxel size are not recorded; positions are voxel indices. Every voxel uses colour
// index 1 of the default palette, so no RGBA chunk is written.
#include <algorithm>
#include <limits>
#include <map>
#include <sstream>
#include <vector>

#include "atomic_file.hpp"
#include "writers.hpp"

namespace oclvox::detail {

namespace {

constexpr int64_t kTile = 256;
constexpr uint8_t kColorIndex = 1;
// 150 is the version MagicaVoxel 0.99 wrote when it introduced the scene graph chunks; readers
// that know the scene graph accept it.
constexpr int32_t kVersion = 150;

using Tile = std::array<int64_t, 3>;        // tile coordinates (voxel index / 256)
using LocalVoxel = std::array<uint8_t, 3>;  // voxel within its tile

// Chunk: 4-byte id, content size, children size, content, children.
void write_chunk(std::ostream& out, const char* id, const std::string& content,
                 const std::string& children = "") {
    out.write(id, 4);
    write_le_i32(out, int32_t(content.size()));
    write_le_i32(out, int32_t(children.size()));
    out << content << children;
}

void write_string(std::ostream& out, const std::string& text) {
    write_le_i32(out, int32_t(text.size()));
    out << text;
}

// DICT of key/value strings.
void write_dict(std::ostream& out, const std::vector<std::pair<std::string, std::string>>& dict) {
    write_le_i32(out, int32_t(dict.size()));
    for (const auto& [key, value] : dict) {
        write_string(out, key);
        write_string(out, value);
    }
}

// nTRN with one frame. The root has no layer (-1) and no translation.
std::string transform_node(int32_t id, int32_t child, int32_t layer,
                           const std::string& translation) {
    std::ostringstream out;
    write_le_i32(out, id);
    write_dict(out, {});
    write_le_i32(out, child);
    write_le_i32(out, -1);  // reserved
    write_le_i32(out, layer);
    write_le_i32(out, 1);  // frames
    if (translation.empty())
        write_dict(out, {});
    else
        write_dict(out, {{"_t", translation}});
    return out.str();
}

std::string group_node(int32_t id, const std::vector<int32_t>& children) {
    std::ostringstream out;
    write_le_i32(out, id);
    write_dict(out, {});
    write_le_i32(out, int32_t(children.size()));
    for (int32_t child : children) write_le_i32(out, child);
    return out.str();
}

std::string shape_node(int32_t id, int32_t model) {
    std::ostringstream out;
    write_le_i32(out, id);
    write_dict(out, {});
    write_le_i32(out, 1);  // models
    write_le_i32(out, model);
    write_dict(out, {});
    return out.str();
}

std::string layer_chunk(int32_t id) {
    std::ostringstream out;
    write_le_i32(out, id);
    write_dict(out, {});
    write_le_i32(out, -1);  // reserved
    return out.str();
}

}  // namespace

void write_vox(const std::string& path, const SparseVoxels& voxels) {
    const Grid& grid = voxels.grid();

    // Phase 1: sort the set voxels into tiles. An empty grid still gets one (empty) model so the
    // file has the structure every reader expects.
    std::map<Tile, std::vector<LocalVoxel>> tiles;
    voxels.for_each([&](int64_t i, int64_t j, int64_t k) {
        tiles[{i / kTile, j / kTile, k / kTile}].push_back(
            {uint8_t(i % kTile), uint8_t(j % kTile), uint8_t(k % kTile)});
    });
    if (tiles.empty()) tiles[{0, 0, 0}];

    // Phase 2: the children of MAIN: models first (a model's id is its position among them),
    // then the scene graph. Node ids: 0 root transform, 1 group, then 2m + 2 and 2m + 3 for the
    // transform and shape of model m.
    std::ostringstream children;
    std::vector<int32_t> group_children;
    std::ostringstream scene;
    int32_t model = 0;
    for (auto& [tile, local] : tiles) {
        std::sort(local.begin(), local.end());  // same file whatever the brick order
        std::array<int64_t, 3> size{}, centre{};
        for (int a = 0; a < 3; ++a) {
            const int64_t start = tile[a] * kTile;
            size[a] = std::min(kTile, grid.dims[a] - start);
            centre[a] = start + size[a] / 2;
        }

        std::ostringstream size_content, xyzi_content;
        for (int a = 0; a < 3; ++a) write_le_i32(size_content, int32_t(size[a]));
        write_le_i32(xyzi_content, int32_t(local.size()));
        for (const LocalVoxel& v : local) {
            xyzi_content.write(reinterpret_cast<const char*>(v.data()), 3);
            xyzi_content.put(char(kColorIndex));
        }
        write_chunk(children, "SIZE", size_content.str());
        write_chunk(children, "XYZI", xyzi_content.str());

        const int32_t transform_id = 2 * model + 2, shape_id = transform_id + 1;
        group_children.push_back(transform_id);
        const std::string translation = std::to_string(centre[0]) + " " +
                                        std::to_string(centre[1]) + " " + std::to_string(centre[2]);
        write_chunk(scene, "nTRN", transform_node(transform_id, shape_id, 0, translation));
        write_chunk(scene, "nSHP", shape_node(shape_id, model));
        ++model;
    }
    write_chunk(children, "nTRN", transform_node(0, 1, -1, ""));
    write_chunk(children, "nGRP", group_node(1, group_children));
    children << scene.str();
    write_chunk(children, "LAYR", layer_chunk(0));

    // Phase 3: the file is the magic, the version and the MAIN chunk around everything else.
    const std::string main_children = children.str();
    if (main_children.size() > size_t(std::numeric_limits<int32_t>::max()))
        throw OutputError("cannot write " + path + ": " + std::to_string(voxels.count()) +
                          " voxels exceed the 2 GiB a .vox file can hold");
    write_file_atomically(path, [&](std::ostream& out) {
        out.write("VOX ", 4);
        write_le_i32(out, kVersion);
        write_chunk(out, "MAIN", "", main_children);
    });
}

}  // namespace oclvox::detail
